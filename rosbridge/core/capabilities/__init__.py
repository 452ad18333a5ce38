"""The bridge's capabilities, one module per group of operations (as rosbridge_library's).

``topics`` (advertise, publish, subscribe...), ``services`` (call, provide, time out) and
``graph`` (the relay to a ROS 2 graph with ``--ros``). Each works on the per-client
``Session`` objects of one ``Bridge``; adding an op touches one module and the schema.
"""
