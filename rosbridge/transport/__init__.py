"""The rosbridge WebSocket server: front door, connections, tick schedule, wire frames."""
