"""Measurements of the pipeline, not the pipeline: accuracy against time knob by knob
(``symdrive bench accuracy-time``: :mod:`.knobs`, :mod:`.accuracy_time`) and the renderer's
baseline frame that ``scripts/bench_render.py`` times today's kernels against
(:mod:`.kernels_baseline`, :mod:`.rasterize_baseline`).

Nothing under ``pipeline/`` imports this package.
"""
