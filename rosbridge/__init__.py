"""The rosbridge v2 protocol as a library that knows no robot and no class.

Layers, each importing only those below it (import-linter contracts in pyproject.toml):

* ``transport``: the WebSocket front door, one connection object per client, the tick
  schedule, frames serialized once (asyncio and websockets);
* ``graph``: the rclpy side of ``--ros``: relays for topics, services and actions;
* ``core``: the protocol without I/O: schema, encodings, fragments, limits, access,
  sessions and outboxes, the bridge and its capabilities (one module per op family);
* ``msgs``: message values, definitions and checks, canonical form, CDR, typedefs and the
  rclpy conversion.
"""
