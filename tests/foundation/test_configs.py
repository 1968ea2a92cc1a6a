"""Defaults live in config dataclasses that import no torch, and the pipeline's options compose
them: the command line, the planner and the cache key read them without loading a model."""

import subprocess
import sys
from dataclasses import fields, is_dataclass, replace

import pytest

from symdrive_core.diffusion import config as diffusion_config
from symdrive_core.diffusion.adapt import AdaptConfig
from symdrive_core.insertion import config as insertion_config
from symdrive_core.optim import config as optim_config
from symdrive_core.pipeline.cache_key import inputs_key
from symdrive_core.pipeline.stages import StageOptions
from tests.foundation.test_numpy_only_imports import HIDE

CONFIG_MODULES = ["symdrive_core.diffusion.config", "symdrive_core.optim.config", "symdrive_core.insertion.config",
                  "symdrive_core.diffusion.adapt", "symdrive_core.pipeline.stages"]


@pytest.mark.parametrize("module", CONFIG_MODULES)
def test_config_module_imports_without_torch(module):
    code = HIDE + f"import {module}\nassert 'torch' not in sys.modules\nprint('ok')\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_the_code_that_uses_each_config_names_the_same_class():
    """A config moved beside its code, not copied: the torch modules import the one class."""
    from symdrive_core.diffusion import flux_train, refine, sampler, train, unet
    from symdrive_core.insertion import insert
    from symdrive_core.optim import densify, finetune, reconstruct

    pairs = [(sampler.SamplerConfig, diffusion_config.SamplerConfig), (train.TrainConfig, diffusion_config.TrainConfig),
             (refine.RefineConfig, diffusion_config.RefineConfig), (unet.UNetConfig, diffusion_config.UNetConfig),
             (flux_train.FluxTrainConfig, diffusion_config.FluxTrainConfig),
             (reconstruct.ReconstructConfig, optim_config.ReconstructConfig),
             (densify.DensifyConfig, optim_config.DensifyConfig), (finetune.FinetuneConfig, optim_config.FinetuneConfig),
             (insert.InsertionConfig, insertion_config.InsertionConfig)]
    for used, home in pairs:
        assert used is home


def test_stage_options_compose_the_library_configs():
    options = StageOptions()
    composed = {f.name: getattr(options, f.name) for f in fields(options) if is_dataclass(getattr(options, f.name))}
    assert set(composed) == {"sampler", "refine", "harmonize", "inpaint", "insertion", "adapt"}
    assert options.refine == diffusion_config.RefineConfig()
    assert options.harmonize == insertion_config.HarmonizeConfig()
    assert options.inpaint == insertion_config.InpaintConfig()
    assert options.insertion == insertion_config.InsertionConfig()
    assert options.adapt == AdaptConfig()
    # the built-in backend's sampler, with the run's fixed memory budget
    assert replace(options.sampler, max_memory_gib=None) == diffusion_config.SAMPLERS["builtin"]
    assert options.sampler.max_memory_gib > 0


@pytest.mark.parametrize("change", [
    lambda o: replace(o, sampler=replace(o.sampler, samples=o.sampler.samples + 1)),
    lambda o: replace(o, refine=replace(o.refine, iters=o.refine.iters + 1)),
    lambda o: replace(o, harmonize=replace(o.harmonize, start_fraction=o.harmonize.start_fraction / 2)),
    lambda o: replace(o, insertion=replace(o.insertion, finetune=replace(o.insertion.finetune, steps=1))),
])
def test_a_nested_config_field_changes_the_cache_key(make_package, change):
    from symdrive_core.scene import load_manifest

    manifest = load_manifest(make_package(actors=()))
    options = StageOptions()
    key = inputs_key(manifest, None, options)
    assert inputs_key(manifest, None, StageOptions()) == key
    assert inputs_key(manifest, None, change(options)) != key
