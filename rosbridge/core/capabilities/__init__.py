"""The bridge's capabilities, one module per family of operations (as rosbridge_library's).

``topics`` (advertise, publish, subscribe...), ``services`` (call, provide, time out) and
``actions`` (goals, feedback, results, cancels). Each works on the per-client ``Session``
objects of one bridge through a ``BridgeContext`` (``rosbridge.core.context``), never through
the ``Bridge`` nor through another capability; adding an op touches one module and the
schema.
"""
