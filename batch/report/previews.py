"""PNG previews of linear images for the summary and the Blender panel (EXRs stay the data)."""
import numpy as np
from PIL import Image


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def save_linear(path, img, exposure=1.0):
    Image.fromarray((srgb_encode(img[..., :3] * exposure) * 255 + 0.5).astype(np.uint8)).save(path)


def save_signed(path, values, scale):
    """Diverging map: blue negative, red positive, white zero; |value| = scale is saturated."""
    v = np.clip(np.asarray(values, dtype=np.float64) / max(scale, 1e-30), -1, 1)
    rgb = np.stack([1 - np.maximum(-v, 0), 1 - np.abs(v), 1 - np.maximum(v, 0)], axis=-1)
    Image.fromarray((rgb * 255 + 0.5).astype(np.uint8)).save(path)


def save_gray(path, values, scale=1.0):
    v = np.clip(np.asarray(values, dtype=np.float64) / max(scale, 1e-30), 0, 1)
    Image.fromarray((v * 255 + 0.5).astype(np.uint8)).save(path)
