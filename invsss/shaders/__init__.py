"""The reference HLSL shader (docs/renderer.md) and a runner that builds it and runs it on Vulkan.

The ``.hlsl`` files in this folder are the screen-space passes of docs/model.md
written as compute shaders that consume exactly the constants
``invsss export --format hlsl`` writes (``#include "invsss_constants.hlsl"``).
:func:`compile_entry` builds one entry point with Khronos's ``glslangValidator``
(Debian's ``glslang-tools``) into SPIR-V, and :func:`run_shader` dispatches the
passes of a model through ``wgpu`` (``pip install "invsss[shader]"``) on a
Vulkan device, the CPU driver lavapipe (Debian's ``mesa-vulkan-drivers``) or a
GPU, and returns the image: the test suite compares it with :func:`invsss.render`.

Nothing here is imported by ``import invsss``; ``wgpu`` is imported on first use.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..forward.models import MODEL_TABLE, get_model
from ..validation import InvalidInputError

__all__ = [
    "SHADER_DIR",
    "SHADER_FILES",
    "CONSTANTS_FILE",
    "MODEL_SHADERS",
    "shader_sources",
    "find_compiler",
    "compile_entry",
    "vulkan_adapters",
    "run_shader",
    "ShaderUnavailable",
]

#: The folder holding the ``.hlsl`` files (installed as package data).
SHADER_DIR = Path(__file__).resolve().parent
#: The name the shaders include the exported constants by.
CONSTANTS_FILE = "invsss_constants.hlsl"
#: Every shader file, in the order a reader meets them.
SHADER_FILES = (
    "invsss_common.hlsl",
    "invsss_seven_tap.hlsl",
    "invsss_sog.hlsl",
    "invsss_thesis.hlsl",
    "invsss_separable.hlsl",
    "invsss_burley.hlsl",
    "invsss_law.hlsl",
    "invsss_light_terms.hlsl",
    "invsss_transmission.hlsl",
)
#: For each model: the file and the entry points it runs.
#: Each model's reference shader: its HLSL file and entry points (the model
#: table's ``shader`` field, :mod:`invsss.forward.models`), by model name.
MODEL_SHADERS = {name: entry.shader for name, entry in MODEL_TABLE.items()}


class ShaderUnavailable(RuntimeError):
    """No HLSL compiler or no Vulkan device: the message says which and how to get it."""


def shader_sources(constants_name: str = CONSTANTS_FILE, *, model: str | None = None) -> dict[str, str]:
    """The text of the shader files, by name, each including ``constants_name`` for the constants.

    Parameters
    ----------
    constants_name : str
        The file name the shaders ``#include`` the exported constants by
        (default ``invsss_constants.hlsl``).
    model : str, optional
        A key of :data:`MODEL_SHADERS`: only the files that model's shader
        needs, its own file and the files it includes (the light terms' files,
        ``invsss_law.hlsl``, ``invsss_transmission.hlsl`` and ``invsss_light_terms.hlsl``,
        are not part of any model's). Default: every file of :data:`SHADER_FILES`.

    Returns
    -------
    dict
        File name to text, in the order of :data:`SHADER_FILES`.

    Raises
    ------
    InvalidInputError
        A ``model`` that has no reference shader.

    Examples
    --------
    >>> list(shader_sources(model="separable"))
    ['invsss_common.hlsl', 'invsss_separable.hlsl']
    """
    names = SHADER_FILES if model is None else _model_files(model)
    out = {}
    for name in names:
        text = (SHADER_DIR / name).read_text()
        if constants_name != CONSTANTS_FILE:
            text = text.replace(f'#include "{CONSTANTS_FILE}"', f'#include "{constants_name}"')
        out[name] = text
    return out


def _model_files(model) -> tuple[str, ...]:
    """The files of ``model``'s shader: its own and, transitively, what it includes (not the constants)."""
    if not isinstance(model, str) or model not in MODEL_SHADERS:
        raise InvalidInputError(
            f"model: expected one of {', '.join(MODEL_SHADERS)} (a reference shader), got {model!r}",
            field="model",
        )
    needed, todo = set(), [MODEL_SHADERS[model][0]]
    while todo:
        name = todo.pop()
        if name in needed:
            continue
        needed.add(name)
        for line in (SHADER_DIR / name).read_text().splitlines():
            words = line.split()
            if len(words) == 2 and words[0] == "#include":
                included = words[1].strip('"')
                if included != CONSTANTS_FILE:
                    todo.append(included)
    return tuple(name for name in SHADER_FILES if name in needed)


def find_compiler() -> str | None:
    """The path of ``glslangValidator`` (``$GLSLANG_VALIDATOR`` first), or None."""
    given = os.environ.get("GLSLANG_VALIDATOR")
    if given:
        return given if Path(given).is_file() else None
    return shutil.which("glslangValidator")


def compile_entry(hlsl_file, entry: str, include_dir, *, compiler: str | None = None) -> tuple[bytes, str]:
    """SPIR-V of one compute entry point of an HLSL file, and the compiler's messages.

    ``glslangValidator -D -V -S comp -e ENTRY -I INCLUDE_DIR FILE``. The messages
    are what it printed besides the file's name (empty when it had nothing to
    say: no warning). Raises :class:`ShaderUnavailable` without a compiler and
    RuntimeError when the compilation fails.
    """
    compiler = compiler or find_compiler()
    if compiler is None:
        raise ShaderUnavailable(
            "glslangValidator not found: install Debian's glslang-tools (apt-get install glslang-tools) "
            "or set GLSLANG_VALIDATOR"
        )
    with tempfile.TemporaryDirectory() as tmp:
        spv = Path(tmp) / "out.spv"
        done = subprocess.run(
            [compiler, "-D", "-V", "-S", "comp", "-e", entry, f"-I{include_dir}", str(hlsl_file), "-o", str(spv)],
            capture_output=True, text=True,
        )
        # It prints the file's name (as given) before anything it has to say.
        lines = [line for line in (done.stdout + done.stderr).splitlines()
                 if line.strip() and line.strip() not in (str(hlsl_file), Path(hlsl_file).name)]
        messages = "\n".join(lines)
        if done.returncode != 0:
            raise RuntimeError(f"glslangValidator failed on {hlsl_file} -e {entry}:\n{messages}")
        return spv.read_bytes(), messages


def _wgpu():
    try:
        import wgpu
    except ImportError:
        raise ShaderUnavailable('the Python package wgpu is missing: pip install "invsss[shader]"') from None
    return wgpu


def vulkan_adapters() -> list:
    """The Vulkan adapters wgpu sees (lavapipe is one, a GPU another), or [] without wgpu or Vulkan."""
    try:
        wgpu = _wgpu()
    except ShaderUnavailable:
        return []
    try:
        adapters = wgpu.gpu.enumerate_adapters_sync()
    except Exception:  # no driver, no loader: no adapter
        return []
    return [a for a in adapters if str(a.info.get("backend_type", "")).lower() == "vulkan"]


_DEVICES: dict = {}
# The storage textures are read and written (AccumulateCS): rgba32float storage
# with read-write access needs this wgpu feature (lavapipe and desktop GPUs have it).
_FEATURE = "texture-adapter-specific-format-features"


def _device(adapter_name: str | None):
    key = adapter_name or ""
    if key in _DEVICES:
        return _DEVICES[key]
    adapters = vulkan_adapters()
    if adapter_name:
        adapters = [a for a in adapters if adapter_name.lower() in a.info["device"].lower()]
    adapters = [a for a in adapters if _FEATURE in a.features]
    if not adapters:
        what = f" named like {adapter_name!r}" if adapter_name else ""
        raise ShaderUnavailable(
            f"no Vulkan device{what} with wgpu's {_FEATURE}: install Mesa's lavapipe "
            "(apt-get install mesa-vulkan-drivers) or a GPU driver"
        )
    device = adapters[0].request_device_sync(required_features=[_FEATURE])
    _DEVICES[key] = device
    return device


class _Runner:
    """Textures, pipelines and dispatches of one image size on one device."""

    def __init__(self, device, shape):
        self.wgpu = _wgpu()
        self.device = device
        self.h, self.w = shape
        wgpu = self.wgpu
        texture = {"sample_type": wgpu.TextureSampleType.unfilterable_float,
                   "view_dimension": wgpu.TextureViewDimension.d2}
        entries = [{"binding": 0, "visibility": wgpu.ShaderStage.COMPUTE,
                    "buffer": {"type": wgpu.BufferBindingType.uniform}}]
        entries += [{"binding": b, "visibility": wgpu.ShaderStage.COMPUTE, "texture": texture} for b in range(1, 7)]
        entries.append({"binding": 7, "visibility": wgpu.ShaderStage.COMPUTE,
                        "storage_texture": {"access": wgpu.StorageTextureAccess.read_write,
                                            "format": wgpu.TextureFormat.rgba32float,
                                            "view_dimension": wgpu.TextureViewDimension.d2}})
        entries += [{"binding": b, "visibility": wgpu.ShaderStage.COMPUTE, "texture": texture} for b in (8, 9, 10)]
        self.group_layout = device.create_bind_group_layout(entries=entries)
        self.layout = device.create_pipeline_layout(bind_group_layouts=[self.group_layout])
        self.pending = []

    def texture(self, data):
        """An rgba32float (4 channels) or r32float (2D data) texture holding ``data``."""
        wgpu = self.wgpu
        data = np.ascontiguousarray(data, np.float32)
        fmt = wgpu.TextureFormat.r32float if data.ndim == 2 else wgpu.TextureFormat.rgba32float
        usage = (wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST | wgpu.TextureUsage.COPY_SRC
                 | (wgpu.TextureUsage.STORAGE_BINDING if data.ndim == 3 else 0))
        tex = self.device.create_texture(size=(self.w, self.h, 1), format=fmt, usage=usage)
        texel = 4 if data.ndim == 2 else 16
        self.device.queue.write_texture({"texture": tex}, data, {"bytes_per_row": self.w * texel,
                                                                 "rows_per_image": self.h}, (self.w, self.h, 1))
        return tex

    def pipeline(self, spirv: bytes, entry: str):
        module = self.device.create_shader_module(code=spirv)
        return self.device.create_compute_pipeline(layout=self.layout, compute={"module": module, "entry_point": entry})

    def dispatch(self, pipeline, resources: dict, pass_index=0, pass_axis=0):
        uniform = self.device.create_buffer_with_data(
            data=np.array([pass_index, pass_axis, 0, 0], np.uint32), usage=self.wgpu.BufferUsage.UNIFORM)
        entries = [{"binding": 0, "resource": {"buffer": uniform, "offset": 0, "size": 16}}]
        entries += [{"binding": b, "resource": resources[b].create_view()} for b in range(1, 11)]
        group = self.device.create_bind_group(layout=self.group_layout, entries=entries)
        encoder = self.device.create_command_encoder()
        compute = encoder.begin_compute_pass()
        compute.set_pipeline(pipeline)
        compute.set_bind_group(0, group)
        compute.dispatch_workgroups((self.w + 7) // 8, (self.h + 7) // 8, 1)
        compute.end()
        self.pending.append(encoder.finish())

    def read(self, tex) -> np.ndarray:
        self.device.queue.submit(self.pending)
        self.pending = []
        row = (self.w * 16 + 255) // 256 * 256
        raw = self.device.queue.read_texture({"texture": tex}, {"bytes_per_row": row, "rows_per_image": self.h},
                                             (self.w, self.h, 1))
        data = np.frombuffer(raw, np.float32).reshape(self.h, row // 4)[:, : self.w * 4]
        return data.reshape(self.h, self.w, 4).copy()


def _rgba(image, h, w) -> np.ndarray:
    a = np.asarray(image, np.float64)
    if a.ndim == 2:
        a = a[..., None]
    out = np.zeros((h, w, 4), np.float32)
    out[..., : a.shape[2]] = a
    return out


def run_shader(
    image, depth, mask, constants_hlsl: str, model: str, *, normal=None, light=None, key=None, fill_light=None,
    thickness=None, key_irradiance=None, law: bool = False, transmission: bool = False, after_blur: bool = False,
    adapter_name: str | None = None, compiler: str | None = None, messages: list | None = None,
) -> np.ndarray:
    """Run the reference shader of ``model`` on one image; returns (H, W, C) float32.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear radiance without scattering.
    depth : array, shape (H, W)
        Linear eye depth, > 0 everywhere (off the mask too: see
        :func:`invsss.forward.pair.fill_background_depth`, which ``invsss.render`` applies).
    mask : array, shape (H, W)
    constants_hlsl : str
        The text ``invsss export --format hlsl`` writes (or :func:`invsss.io.export.to_hlsl`);
        it becomes ``invsss_constants.hlsl`` beside the shaders.
    model : {"sog", "thesis", "separable", "burley"}
        The constants must be of this model (``burley``: a burley fit's, whose
        ``shapeParameters`` the shader reads).
    normal, light, key, fill_light : arrays, optional
        The light terms' buffers (view-space unit vectors (H, W, 3); the key
        light's part of the source, shaped like ``image``; the direction towards
        the other lights, for a constants text with the fill term).
    thickness, key_irradiance : arrays, optional
        The transmission term's buffers: mm the key light crosses, (H, W); the albedo
        times the key light's unshadowed irradiance, shaped like ``image``.
    law, transmission, after_blur : bool
        Run LawCS and then TransmissionCS before the blur, LightTermsCS after it.
    adapter_name : str, optional
        A part of the Vulkan device's name ("llvmpipe", "NVIDIA"); the first one otherwise.
    messages : list, optional
        Receives the compiler's messages per entry point (file, entry, text).
    """
    if model not in MODEL_SHADERS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODEL_SHADERS)}, got {model!r}", field="model")
    device = _device(adapter_name)
    h, w = np.shape(depth)
    channels = 1 if np.ndim(image) == 2 else np.shape(image)[2]
    runner = _Runner(device, (h, w))
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, CONSTANTS_FILE).write_text(constants_hlsl)
        for name in SHADER_FILES:
            shutil.copy(SHADER_DIR / name, Path(tmp, name))

        def build(file, entry):
            spirv, text = compile_entry(Path(tmp, file), entry, tmp, compiler=compiler)
            if messages is not None:
                messages.append((file, entry, text))
            return runner.pipeline(spirv, entry)

        file, entries = MODEL_SHADERS[model]
        pipes = {entry: build(file, entry) for entry in entries}
        if law:
            pipes["LawCS"] = build("invsss_law.hlsl", "LawCS")
        if transmission:
            pipes["TransmissionCS"] = build("invsss_transmission.hlsl", "TransmissionCS")
        if after_blur:
            pipes["LightTermsCS"] = build("invsss_light_terms.hlsl", "LightTermsCS")

    zero = np.zeros((h, w, 4), np.float32)
    res = {2: runner.texture(depth), 3: runner.texture(mask),
           4: runner.texture(zero if normal is None else _rgba(normal, h, w)),
           5: runner.texture(zero if light is None else _rgba(light, h, w)),
           6: runner.texture(zero if key is None else _rgba(key, h, w)),
           8: runner.texture(zero if fill_light is None else _rgba(fill_light, h, w)),
           9: runner.texture(np.zeros((h, w), np.float32) if thickness is None
                             else np.asarray(thickness, np.float32).reshape(h, w)),
           10: runner.texture(zero if key_irradiance is None else _rgba(key_irradiance, h, w))}
    a, b = runner.texture(_rgba(image, h, w)), runner.texture(zero)

    def run(entry, src, dst, index=0, axis=0):
        runner.dispatch(pipes[entry], {**res, 1: src, 7: dst}, index, axis)

    if law:
        run("LawCS", a, b)
        a, b = b, a
    if transmission:
        run("TransmissionCS", a, b)
        a, b = b, a
    passes = _num_passes(constants_hlsl)
    layout = get_model(model).layout
    if layout == "layered":
        accum = runner.texture(zero)
        for i in range(passes):
            run("BlurPassCS", a, b, i, 0)
            run("BlurPassCS", b, a, i, 1)
            run("AccumulateCS", a, accum, i)
        a, b = accum, b
    elif layout == "chained":
        for axis in (0, 1):
            for i in range(passes):
                run("BlurPassCS", a, b, i, axis)
                a, b = b, a
    elif layout == "kernel":
        for axis in (0, 1):
            run("SeparablePassCS", a, b, 0, axis)
            a, b = b, a
    else:  # "disk" (burley): one gather over the disk
        run("BurleyDiskCS", a, b)
        a, b = b, a
    if after_blur:
        run("LightTermsCS", a, b)
        a = b
    return runner.read(a)[..., :channels]


def _num_passes(constants_hlsl: str) -> int:
    """``numPasses`` of an exported constants text (the host loops over the passes)."""
    for line in constants_hlsl.splitlines():
        if line.startswith("static const int numPasses ="):
            return int(line.split("=")[1].strip().rstrip(";"))
    return 0
