"""Captions burnt into rendered images (Pillow, which imageio depends on)."""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["write_text"]


@functools.lru_cache(maxsize=8)
def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)  # Pillow >= 10.1: a scalable font
    except TypeError:  # older Pillow: the fixed bitmap font
        return ImageFont.load_default()


def write_text(image: np.ndarray, text: str, at: tuple[int, int] = (4, 3)) -> np.ndarray:
    """``image`` (H, W, 3 uint8) with ``text`` in white on a black box at pixel ``at``
    (x, y from the top-left); the font is about 1/26 of the image height."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(np.ascontiguousarray(image))
    draw = ImageDraw.Draw(img)
    font = _font(max(10, image.shape[0] // 26))
    left, top, right, bottom = draw.textbbox(at, text, font=font)
    draw.rectangle((left - 3, top - 2, right + 3, bottom + 2), fill=(0, 0, 0))
    draw.text(at, text, fill=(255, 255, 255), font=font)
    return np.asarray(img)
