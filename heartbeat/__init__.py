"""The simulator's heartbeat: the one tick driver of a server and the paces it keeps."""
