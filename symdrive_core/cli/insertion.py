"""``symdrive insert`` (render a vehicle inserted along its trajectory) and ``symdrive
insert-eval`` (insertion metrics on the package's held-out placements)."""

from __future__ import annotations

from pathlib import Path

from ..insertion.config import MESH_SAMPLES, HarmonizeConfig
from ..optim.config import FinetuneConfig
from . import (
    add_json_option,
    add_quiet_option,
    add_renamed_option,
    count_int,
    default_of,
    given,
    positive_int,
)


def add_commands(sub) -> None:
    from . import add_external_assets_option

    p = sub.add_parser("insert", help="insert a vehicle actor into the background splats: frames, masks, regions")
    p.add_argument("package", help="scene package directory or manifest.json")
    p.add_argument("--actor", required=True, help="id of the actor to insert")
    add_renamed_option(p, "--gaussians", "--background", type=Path, metavar="PLY",
                       help="reconstruction PLY (default: the manifest's background splats)")
    p.add_argument("--out", help="output directory (default: <package output>/insert)")
    p.add_argument("--flip-forward", action="store_true", help="turn the asset half a turn (forward = -X assets)")
    p.add_argument("--from-mesh", action="store_true", help="sample the asset's mesh instead of its splat PLY")
    p.add_argument("--mesh-gaussians", type=positive_int, metavar="N",
                   help=f"with --from-mesh: Gaussians sampled from the mesh (default {MESH_SAMPLES})")
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_insert)

    p = sub.add_parser("insert-eval", help="naive / colour transfer / harmonized / fine-tuned insertion metrics")
    p.add_argument("package", help="scene package with ground_truth.insertion")
    add_renamed_option(p, "--gaussians", "--background", type=Path, metavar="PLY", required=True,
                       help="reconstruction PLY")
    p.add_argument("--no-harmonize", action="store_true", help="baselines only (no diffusion model loaded)")
    p.add_argument("--steps", type=positive_int,
                   help=f"harmonization sampler steps (default {default_of(HarmonizeConfig, 'steps')})")
    add_renamed_option(p, "--samples", "--harmonize-samples", type=positive_int,
                       help=f"harmonizations averaged per frame (default {default_of(HarmonizeConfig, 'samples')})")
    p.add_argument("--weights", help="built-in restorer weights for harmonization (default: the shipped ones)")
    add_renamed_option(p, "--finetune-iters", "--finetune-steps", type=count_int,
                       help=f"colour/opacity fine-tune iterations per vehicle (default {default_of(FinetuneConfig, 'steps')})")
    p.add_argument("--features-module", help="feature extractor for the Frechet distance: FILE.py:FN, "
                   "MODULE:FN or a TorchScript .pt (never downloaded)")
    p.add_argument("--assets-out", help="write the fine-tuned assets (splat PLY) here")
    add_json_option(p, "the rows and details", optional_file=False)
    add_quiet_option(p)
    add_external_assets_option(p)
    p.set_defaults(func=_insert_eval)


def _insert(args) -> int:
    from ..insertion.render_actor import insert_actor
    from ..pipeline.outputs import own_folder
    from ..scene import check_files, load_manifest

    manifest = load_manifest(args.package, allow_external=args.allow_external_assets)
    check_files(manifest)
    tree = own_folder(args.out if args.out else manifest.output_dir() / "insert")
    for cam in manifest.cameras:  # the frames are written under a folder per camera
        tree.folder(cam.name)
    out = tree.root
    n = insert_actor(manifest, args.actor, out, background=args.gaussians, flip=args.flip_forward,
                     from_mesh=args.from_mesh, progress=not args.quiet, **given(args, n_samples="mesh_gaussians"))
    print(f"wrote {n} frame(s) of {args.actor} to {out}")
    return 0


def _insert_eval(args) -> int:
    from ..eval.insertion import evaluate_insertion
    from ..insertion.config import InsertionConfig
    from ..insertion.features import load_extractor
    from ..io.ply import read_splats
    from ..pipeline.outputs import output_folder
    from ..scene import check_files, load_manifest
    from ..scene.ground_truth import require_truth
    from . import print_json, write_json

    if args.no_harmonize:  # the fine-tune fits the harmonized frames: without them these would do nothing
        from ..errors import InputError

        for option, value in (("--steps", args.steps), ("--samples", args.samples),
                              ("--finetune-iters", args.finetune_iters), ("--assets-out", args.assets_out),
                              ("--weights", args.weights)):
            if value is not None:
                raise InputError("insert-eval", "harmonizes and fine-tunes, which --no-harmonize leaves out", option)
    if args.assets_out:
        output_folder(args.assets_out, "--assets-out")
    manifest = load_manifest(args.package, allow_external=args.allow_external_assets)
    check_files(manifest)
    require_truth(manifest, "insertion", "insert-eval needs it; `symdrive insert` renders a vehicle without scoring")
    harmonizer = None
    if not args.no_harmonize:
        from ..diffusion.models import load_restorer
        from ..insertion.harmonizer import restorer_harmonizer

        harmonizer = restorer_harmonizer(load_restorer(weights=args.weights),
                                         HarmonizeConfig(**given(args, "steps", "samples")))
    cfg = InsertionConfig(finetune=FinetuneConfig(**given(args, steps="finetune_iters")),
                          assets_out=Path(args.assets_out) if args.assets_out else None)
    details: dict = {}
    rows = evaluate_insertion(manifest, read_splats(args.gaussians, drop_invalid=True), harmonizer=harmonizer,
                              config=cfg, details=details, progress=not args.quiet,
                              extractor=load_extractor(args.features_module) if args.features_module else None)
    result = {"insertion": rows, **details}
    if args.json not in (None, "-"):  # the JSON is printed in any case
        write_json(result, args.json)
    print_json(result)
    return 0
