"""Components of the default demo application (``config/demo_pipeline.xml``).

A small signal pipeline that exercises every part of the runtime a user meets first: ports with each
buffering policy, a periodic and a triggered activity, the main activity, cross-activity operations,
a peer, stamps and latency, and the profiler.
"""
