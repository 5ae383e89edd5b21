"""Image files: PNG through imageio (the ``video`` extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rehabbot.common.extras import missing_module_message
from rehabbot.common.files import atomic_save


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` ``uint8`` image as PNG.

    Parent directories are created. Requires the optional ``imageio`` dependency.

    Returns:
        The path written.

    Raises:
        ImportError: if ``imageio`` is not installed.
        ValueError: if the image has an unsupported shape or dtype.
        OSError: if the file cannot be written.
    """
    try:
        import imageio.v3 as iio
    except ImportError as err:
        raise ImportError(missing_module_message("saving PNG images", "imageio")) from err
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"PNG images must be uint8, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4))):
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got {image.shape}")
    out_path = Path(path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_save(out_path, lambda tmp: iio.imwrite(tmp, image, extension=".png"))
    return out_path
