"""Accuracy against time: each knob's settings measured on a package (``symdrive accuracy-time``).

Benchmarks, not the pipeline: nothing under ``pipeline/`` imports this package.
"""
