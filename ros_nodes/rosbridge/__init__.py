"""The embedded rosbridge v2 server: protocol (Sans-I/O), encodings, services, server."""
