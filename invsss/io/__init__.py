"""File input and output: images, depth, masks and params JSON files.

Three modules, one idea each: :mod:`~invsss.io.colour` (the sRGB transfer
function), :mod:`~invsss.io.images` (pixels in and out, with the decoding
rules and the atomic writer) and :mod:`~invsss.io.params_file` (the params
JSON schema). Their public names are re-exported here.
"""

from .colour import linear_to_srgb, srgb_to_linear
from .images import (
    IMAGE_EXTENSIONS,
    ImagePair,
    clipping_level,
    image_extension,
    load_pair,
    read_depth,
    read_image,
    read_mask,
    shared_clipping_level,
    write_image,
    write_text_atomic,
)
from .params_file import PARAMS_KEYS, PARAMS_OPTIONAL_KEYS, read_params, write_params

__all__ = [
    "IMAGE_EXTENSIONS",
    "clipping_level",
    "image_extension",
    "PARAMS_KEYS",
    "PARAMS_OPTIONAL_KEYS",
    "ImagePair",
    "load_pair",
    "read_depth",
    "read_image",
    "read_mask",
    "read_params",
    "shared_clipping_level",
    "write_image",
    "write_params",
    "write_text_atomic",
    "srgb_to_linear",
    "linear_to_srgb",
]
