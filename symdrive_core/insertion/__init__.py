"""Vehicle insertion: assets, placement, the insertion itself (``insert``), shadows, baselines, evaluation.

Light to import: submodules pull in torch only where they render or optimise.
"""
