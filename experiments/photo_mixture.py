"""A realistic photograph of a path-traced pair, and what the fit makes of it (issue 13).

The bundled path-traced pair (``data_synthetic/pt_face_940`` by default) is the
clean version: its source, depth and mask from the scene's camera, its target
path-traced from the same camera. A "photograph" is made as a camera would make
it, from these nuisances (``--rows`` picks photographs with one of them, or all):

1. ``move``: the scene path-traced again (``--spp``) from a camera moved by
   ``--shift`` pixels (a pan and tilt of ``shift / focal_px`` radians) and rolled
   by ``--roll`` degrees, so nothing is interpolated;
2. ``specular``: the specular reflection of a rough dielectric boundary of the
   medium's refractive index (the scene's ``specular`` pass: the boundary around a
   black interior), added on top, scaled by ``--specular``;
3. ``vignetting``: a radial gain falling to ``1 - --vignetting`` at the corners;
4. ``sensor``: shot noise (2000 electrons at the 99th percentile) and 2 e- read
   noise, then 8-bit sRGB encoding (exposed so the 99.5th percentile is 0.9) and
   the decoding ``invsss.load_pair`` applies to an 8-bit file;
5. ``mixture``: all four; ``rerender``: none, the view path-traced again with
   another seed, which shows how far Monte Carlo noise alone moves a fit.

Each is fitted plainly and as a photograph should be (``--align similarity
--vignetting``; ``--highlights`` adds a fit with that option,
``--light-terms`` puts the light-aware terms in every fit), and compared with the
clean pair fitted the same way. ``--rerender`` adds the final step a photograph
gets: the scene rendered again from the camera the photo fit's registration
found (``invsss scene --warp params.json --source-only``) and the photograph
fitted against that render::

    python experiments/photo_mixture.py [--pair data_synthetic/pt_face_940] [--spp 1024]
        [--rows mixture] [--rerender] [--light-terms shift,grazing,incidence]
        [--shift 1.2 1.6] [--roll 1.0] [--specular 1.0] [--vignetting 0.15] [--starts 2]
        [--cache DIR]

The moved camera's signs were checked by registering its render against the
bundled one (``--check-camera`` prints the warp found for the source pass).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import invsss
from invsss.scenes import parse_config
from invsss.scenes.mitsuba_scene import import_mitsuba, load_mesh_ply, scene_dict
from invsss.scenes.path_tracing import _grey_media, render_scene

from photo_robustness import eight_bit_srgb, shot_noise, vignette


def moved_config(config, shift_px, roll_deg):
    """The scene's config with the camera turned so the picture moves by ``shift_px``
    (rows, columns) and turns by ``roll_deg`` (the registration's sign convention)."""
    camera = config.camera
    position, look_at = np.asarray(camera.position, float), np.asarray(camera.look_at, float)
    forward = (look_at - position) / np.linalg.norm(look_at - position)
    right = np.cross(forward, camera.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    f = camera.focal_length_px
    # Panning the view right moves the picture left; tilting it down moves it up.
    direction = forward - shift_px[1] / f * right + shift_px[0] / f * up
    a = np.radians(roll_deg)
    rolled_up = np.cos(a) * up + np.sin(a) * right
    distance = np.linalg.norm(look_at - position)
    new_camera = camera.model_copy(update={
        "look_at": (position + distance * direction / np.linalg.norm(direction)).tolist(),
        "up": rolled_up.tolist(),
    })
    return config.model_copy(update={"camera": new_camera})


def render_pass(config, kind: str, spp: int, seed: int, medium: dict | None = None, albedo=None) -> np.ndarray:
    """One Mitsuba pass of ``config`` (first channel), (H, W, 1)."""
    mi = import_mitsuba(config.variant)
    with tempfile.TemporaryDirectory(prefix="photo-mixture-") as folder:
        mesh = load_mesh_ply(config.object.mesh, folder) if config.object.mesh else None
        extra = {} if albedo is None else {"albedo": albedo}
        scene = mi.load_dict(scene_dict(mi, config, kind, mesh_ply=mesh, coefficients=medium, **extra))
        image = np.asarray(mi.render(scene, spp=spp, seed=seed), np.float64)
    return image[..., :1]


@dataclasses.dataclass(frozen=True)
class Recipe:
    """Which nuisances a photograph has, each on its own switch so it can be measured alone."""

    move: bool = False
    specular: bool = False
    vignetting: bool = False
    sensor: bool = False  # shot noise, then 8-bit sRGB


# "rerender" has no nuisance: the same view path-traced again with another seed
# (at --spp), so its row is the noise floor the other rows are read against.
RECIPES = {
    "rerender": Recipe(),
    "move": Recipe(move=True),
    "specular": Recipe(specular=True),
    "vignetting": Recipe(vignetting=True),
    "sensor": Recipe(sensor=True),
    "mixture": Recipe(move=True, specular=True, vignetting=True, sensor=True),
}


class Photographer:
    """Makes the photographs of :data:`RECIPES`, rendering each pass it needs once."""

    def __init__(self, config, args):
        self.args = args
        self.views = {False: config, True: moved_config(config, args.shift, args.roll)}
        # The first (for a grey medium, the only) channel's medium, as the scene renderer splits it.
        self.grey = _grey_media(config.medium.coefficients())[0]
        # The boundary a real face has: a rough dielectric of the medium's index.
        update = {"boundary": "rough-dielectric"}
        if args.roughness is not None:
            update["roughness"] = args.roughness
        self.dielectric = config.medium.model_copy(update=update)
        self._passes: dict = {}

    def _pass(self, moved: bool, kind: str) -> np.ndarray:
        if (moved, kind) not in self._passes and self.args.cache is not None:
            a = self.args
            key = f"{a.pair.name}-{kind}-{a.spp}spp"
            if moved:
                key += f"-moved{a.shift[0]:g},{a.shift[1]:g},{a.roll:g}"
            if kind == "specular" and a.roughness is not None:
                key += f"-rough{a.roughness:g}"
            path = a.cache / f"{key}.npy"
            if path.is_file():
                self._passes[moved, kind] = np.load(path)
            else:
                a.cache.mkdir(parents=True, exist_ok=True)
                np.save(path, self._render(moved, kind))
        return self._render(moved, kind)

    def _render(self, moved: bool, kind: str) -> np.ndarray:
        if (moved, kind) not in self._passes:
            started = time.perf_counter()
            view = self.views[moved]
            if kind == "target":
                image = render_pass(view, "target", self.args.spp, 11, self.grey)
            else:
                image = render_pass(view.model_copy(update={"medium": self.dielectric}), "specular",
                                    max(self.args.spp // 4, 16), 12, _grey_media(self.dielectric.coefficients())[0])
            print(f"  rendered the {'moved' if moved else 'same'} view's {kind} pass in "
                  f"{time.perf_counter() - started:.0f} s (peak {image.max():.3g})", flush=True)
            self._passes[moved, kind] = image
        return self._passes[moved, kind]

    def photograph(self, recipe: Recipe) -> np.ndarray:
        """(H, W) float32: the view path-traced, then the optics, then the sensor, in a camera's order."""
        image = self._pass(recipe.move, "target")
        if recipe.specular:
            image = image + self.args.specular * self._pass(recipe.move, "specular")
        if recipe.vignetting:
            image = vignette(image, self.args.vignetting)
        if recipe.sensor:
            image, _ = eight_bit_srgb(shot_noise(image, 2000.0, 2.0, np.random.default_rng(13)))
        return image.astype(np.float32)[..., 0]


def fit_rerendered(config, photo: np.ndarray, options: dict, terms: tuple, starts: int):
    """Fit ``photo`` against ``config``'s source side, rendered without a target, with
    the options of the photo fit: its registration now only has to find what is left
    of the warp, a few hundredths of a pixel, so resampling costs next to nothing."""
    view = render_scene(config, target=False)
    buffers = {"light_buffers": invsss.LightBuffers(normal=view.normal, light=view.light)} if terms else {}
    return invsss.fit_pair(view.source, photo, view.depth, view.mask, n_starts=starts, light_terms=terms,
                           **buffers, **options)


def _pm(value) -> str:
    return "" if value is None else f" +- {value:.0f}"


def _found(fit, terms: tuple) -> str:
    """What the fit found besides the scattering parameters: warp, vignetting, light terms, highlights."""
    parts = []
    if fit.alignment:
        a = fit.alignment[0]
        parts.append(f"({a['shift_px'][0]:+.2f}, {a['shift_px'][1]:+.2f}) px, {a['rotation_deg']:+.2f} deg")
    if fit.vignetting:
        parts.append(f"corner gain {fit.vignetting['corner_gain']:.3f}")
    if terms:
        parts.append(", ".join(f"{k} {fit.light_terms[k]:.3g}" for k in terms))
    if fit.highlights:
        parts.append(f"{fit.highlights['fraction'][0]:.1%} left out as highlights")
    return "; ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pair", type=Path, default=Path("data_synthetic/pt_face_940"))
    parser.add_argument("--spp", type=int, default=1024)
    parser.add_argument("--shift", type=float, nargs=2, default=(1.2, 1.6), metavar=("ROWS", "COLS"))
    parser.add_argument("--roll", type=float, default=1.0)
    parser.add_argument("--specular", type=float, default=1.0)
    parser.add_argument("--roughness", type=float, default=None,
                        help="Beckmann roughness of the specular boundary (default: the medium's)")
    parser.add_argument("--vignetting", type=float, default=0.15)
    parser.add_argument("--starts", type=int, default=2)
    parser.add_argument("--rows", default="mixture",
                        help=f"comma-separated photographs to fit (default mixture; any of {', '.join(RECIPES)})")
    parser.add_argument("--highlights", action="store_true", help="fit each photograph with --highlights too")
    parser.add_argument("--cache", type=Path, default=None,
                        help="a folder to keep the path-traced passes in between runs")
    parser.add_argument("--rerender", action="store_true",
                        help="after each photo fit, render the scene again from the camera its registration "
                        "found and fit the photograph against that render")
    parser.add_argument("--light-terms", default="",
                        help="comma-separated light-aware terms every fit includes (e.g. shift,grazing,incidence); "
                             "the pair folder's normal.exr and light.exr are their buffers")
    parser.add_argument("--check-camera", action="store_true",
                        help="render the source pass from the moved camera and print the warp registration finds")
    args = parser.parse_args()
    names = args.rows.split(",")
    for name in names:
        if name not in RECIPES:
            parser.error(f"--rows: unknown row {name!r}; expected some of {', '.join(RECIPES)}")
    info = json.loads((args.pair / "scene.json").read_text())
    config = parse_config(info["config"])
    pair = invsss.load_pair(*(args.pair / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    photographer = Photographer(config, args)

    if args.check_camera:
        from invsss.estimator.registration import estimate_warp

        albedo = info["source_albedo"]["value"][0]
        source = render_pass(photographer.views[True], "source", 256, 0, photographer.grey, albedo)
        warp = estimate_warp(source, np.asarray(pair.source, np.float64), np.asarray(pair.mask), "similarity")
        print(json.dumps(warp.to_dict()))
        return

    terms = tuple(args.light_terms.split(",")) if args.light_terms else ()
    light_options = {}
    if terms:
        light_options = {"light_terms": terms,
                         "light_buffers": invsss.LightBuffers(normal=invsss.read_image(args.pair / "normal.exr"),
                                                              light=invsss.read_image(args.pair / "light.exr"))}
    photo_fit = {"align": "similarity", "vignetting": True}
    runs = [("clean", "plain", {}), ("clean", "photo fit", photo_fit)]
    for name in names:
        runs += [(name, "plain", {}), (name, "photo fit", photo_fit)]
        if args.highlights:
            runs.append((name, "photo fit + highlights", dict(photo_fit, highlights=True)))

    if args.rerender:
        runs = [run for name, label, options in runs
                for run in [(name, label, options)] + ([(name, "re-rendered", options)] if label == "photo fit" else [])]

    rows, clean = [], {}
    for name, label, options in runs:
        image = pair.target if name == "clean" else photographer.photograph(RECIPES[name])
        started = time.perf_counter()
        if label == "re-rendered":
            # The scene rendered again from the camera the photo fit's registration found
            # (what `invsss scene --warp params.json --source-only` does) and fitted again.
            fit = fit_rerendered(config.with_warp(fit.alignment[0]), image, options, terms, args.starts)
        else:
            fit = invsss.fit_pair(pair.source, image, pair.depth, pair.mask, n_starts=args.starts, **options,
                                  **light_options)
        # Each fit against the clean pair fitted the same way (a clean pair has no highlights to leave out).
        if name == "clean":
            clean[label] = fit
        ref = clean[label if label in ("plain", "re-rendered") else "photo fit"]

        def cell(key):
            change = 100 * (float(fit.values[key]) / float(ref.values[key]) - 1)
            return f"{float(fit.values[key]):.0f}{_pm(fit.stderr.get(key))} ({change:+.1f} %)"

        rows.append(f"| {name} | {label} | {cell('sss_level')} | {cell('correction')} | "
                    f"{float(fit.values['maxdd']):.3g} | {fit.psnr:.1f} | {_found(fit, terms)} |")
        print(f"  {name}, {label}: {time.perf_counter() - started:.0f} s", flush=True)
    print(f"\n{args.pair}: camera moved ({args.shift[0]}, {args.shift[1]}) px and rolled {args.roll} deg, "
          f"specular x{args.specular} (roughness {photographer.dielectric.roughness}), vignetting "
          f"{args.vignetting:.0%}, shot noise and 8-bit sRGB; light terms: {args.light_terms or 'none'}; "
          f"photo fit = align similarity + vignetting; changes against the clean pair fitted the same way")
    print("| photograph | fit | sss_level | correction | maxdd | PSNR dB | found |\n|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
