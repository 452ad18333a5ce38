"""The rosbridge v2 protocol without I/O: frames in, frames out for the transport to write."""
