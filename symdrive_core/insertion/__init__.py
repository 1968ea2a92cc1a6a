"""Vehicle insertion: assets, placement, shadow regions, baselines, fine-tune inputs, evaluation.

Light to import: submodules pull in torch only where they render or optimise.
"""
