"""``invsss scene``: render a path-traced scene pair with Mitsuba 3."""

from __future__ import annotations

import argparse
import sys

from ..io.result_dir import ResultDir, ResultWriteError
from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "scene",
        help="path-trace a source/target pair from a scene description (needs invsss[scenes])",
        description="Render CONFIG (a TOML scene description: object, camera, lights, "
        "occluders, medium) with Mitsuba 3 into DIR: source.exr (Lambertian), target.exr "
        "(scattering medium, reflection removed), depth.exr (eye z, mm), mask.png, "
        "normal.exr, coverage.exr, the light terms' buffers (light.exr, key.exr, and "
        "fill_light.exr where the scene has other lights), the transmission's (thickness.exr, "
        "thickness_normal.exr, key_irradiance.exr) and scene.json (everything needed to "
        "reproduce it, and the target's noise estimate).",
    )
    parser.add_argument("config", help="scene description (.toml)")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output directory (created if missing); a directory that already "
                        "holds a result is refused unless --overwrite is given")
    parser.add_argument("--overwrite", action="store_true", help="replace the result already in DIR")
    parser.add_argument("--width", type=int, default=None, metavar="PX",
                        help="image width (default: the config's; alone, keeps the aspect ratio)")
    parser.add_argument("--height", type=int, default=None, metavar="PX",
                        help="image height (default: the config's; alone, keeps the aspect ratio)")
    parser.add_argument("--spp", type=int, default=None, metavar="N",
                        help="samples per pixel, even (default: the config's)")
    parser.add_argument("--seed", type=int, default=None, metavar="N", help="seed (default: the config's)")
    parser.add_argument("--warp", default=None, metavar="PARAMS_JSON",
                        help="a fit's params.json whose registration (fit --align translation or similarity) "
                        "moves the camera: the render lands on the photograph's pixel grid, and a fit with "
                        "--align again has only hundredths of a pixel left to resample (see docs/capture.md)")
    parser.add_argument("--source-only", action="store_true",
                        help="leave out the path-traced target: source, depth, mask and buffers only, for "
                        "fitting a photograph (the target is most of the render time)")
    parser.set_defaults(func=run)


def _warp_from_params(path: str):
    """The one warp in a fit's params.json (``alignment``), for ``scene --warp``."""
    from ..io import read_params

    _, extras = read_params(path)
    warps = extras.get("alignment") or []
    if len(warps) != 1:
        found = ("no alignment (the fit ran without --align)" if not warps
                 else f"{len(warps)} warps (a fit of several pairs)")
        raise InvalidInputError(f"--warp {path}: expected the params.json of a fit of one pair with --align, "
                                f"found {found}")
    return warps[0]


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    # Imported here: the scene code needs Mitsuba, which the other commands do not.
    from ..scenes import load_config
    from ..scenes.path_tracing import SCENE_FILES, render_scene, scene_writers

    config = load_config(args.config)
    if args.warp is not None:
        # Before any --width/--height: the warp is in the pixels of the render it was fitted to.
        config = config.with_warp(_warp_from_params(args.warp))
    config = config.with_overrides(
        width=args.width, height=args.height, spp=args.spp, seed=args.seed,
        name=f"{args.config} with --width/--height/--spp/--seed",
    )
    with ResultDir(args.out, overwrite=args.overwrite, names=SCENE_FILES) as out:
        result = render_scene(config, progress=lambda text: print(text, file=sys.stderr, flush=True),
                              target=not args.source_only)
        try:
            written = out.commit(scene_writers(result), {"command": "scene"})
        except ResultWriteError as err:
            print(f"invsss: error: {err}", file=sys.stderr)
            return 1
    noise = result.info["noise"]
    ceiling = "no target" if noise is None else f"target noise ceiling {noise['noise_ceiling_db']:.1f} dB"
    print(
        f"scene: {config.camera.width}x{config.camera.height}, {config.spp} spp, "
        f"{result.info['render_seconds']['total']:.1f} s; {ceiling}; wrote {', '.join(written)}"
    )
    return 0
