"""A class: the roster, the registry of robots, the class server, the instructor's view."""
