"""File input and output: images, depth, masks and params JSON files.

One idea per module: :mod:`~invsss.io.colour` (the sRGB transfer function),
:mod:`~invsss.io.rasters` (which files are read, their codes as stored),
:mod:`~invsss.io.images` (colour images and whole pairs, with the decoding
rules), :mod:`~invsss.io.depth` and :mod:`~invsss.io.masks` (data, never
colour-decoded), :mod:`~invsss.io.writing` (the atomic writers),
:mod:`~invsss.io.params_file` (the params JSON schema),
:mod:`~invsss.io.result_dir` (an output directory as a unit) and
:mod:`~invsss.io.export` (parameters for shaders). The public names of the
first seven are re-exported here.
"""

from .colour import linear_to_srgb, srgb_to_linear
from .depth import read_depth
from .images import clipping_level, load_pair, read_image, resolved_saturation, shared_clipping_level
from .masks import read_mask
from .params_file import PARAMS_KEYS, PARAMS_OPTIONAL_KEYS, read_params, write_params
from .rasters import IMAGE_EXTENSIONS, image_extension
from .writing import write_image, write_text_atomic

__all__ = [
    "IMAGE_EXTENSIONS",
    "clipping_level",
    "image_extension",
    "PARAMS_KEYS",
    "PARAMS_OPTIONAL_KEYS",
    "load_pair",
    "read_depth",
    "read_image",
    "read_mask",
    "read_params",
    "resolved_saturation",
    "shared_clipping_level",
    "write_image",
    "write_params",
    "write_text_atomic",
    "srgb_to_linear",
    "linear_to_srgb",
]
