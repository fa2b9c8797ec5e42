"""Plain numpy references of the library's kernels, for the differential tests (and some benchmarks).

Each module states one kernel's contract in the simplest numpy it can be written in; the tests check that the
kernel gives the same results (the same bits where the kernel promises them). The library never imports them.
"""
