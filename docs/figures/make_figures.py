"""Regenerate the documentation's figures with rimcl's own commands.

    python docs/figures/make_figures.py            # about 5 min on a 2-core CPU with PoCL

Writes docs/_static/figures/*.png (committed, each scaled to at most 1100 px wide):

- error_budget.png, position_error.png, velocity_error.png: the default study
  (`rimcl study --out DIR`, the README's main job);
- tracer_images.png: one tracer through the shipped sample as air (C1) and as water (C4),
  from `rimcl render --frame-image`, cropped around the tracer;
- bench.png: the speed-accuracy chart of `rimcl bench --quick`.
"""

import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
from PIL import Image

OUT = Path(__file__).resolve().parents[1] / "_static" / "figures"
WIDTH = 1100  # px: sharp on a screen, small in the repository


def rimcl(*args, cwd):
    print("rimcl", *args, flush=True)
    subprocess.run([sys.executable, "-m", "rimcl", *args], cwd=cwd, check=True)


def save_scaled(source, name):
    image = Image.open(source)
    if image.width > WIDTH:
        image = image.resize((WIDTH, round(image.height * WIDTH / image.width)), Image.LANCZOS)
    image.convert("RGB").quantize(colors=128).save(OUT / name, optimize=True)
    print("wrote", OUT / name, f"{(OUT / name).stat().st_size / 1024:.0f} KiB")


def tracer_images(work):
    """One tracer imaged through C1 (air) and C4 (water), the same tracer and rays."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    imaging = ["--tracers", "4", "--fan", "32", "--pixels", "2048", "--psf-sigma", "7"]
    imaging += ["--threshold", "40", "--frames", "1"]
    panels = []
    for case in ("C1", "C4"):
        rimcl(
            "render",
            "--case",
            case,
            *imaging,
            "--frame-image",
            f"{case}.png",
            "-o",
            f"{case}.h5",
            cwd=work,
        )
        with h5py.File(work / f"{case}.h5") as f:
            pixel = float(f.attrs["pixel_size"])
            fov_lo = np.asarray(f.attrs["fov_lo"], dtype=float)
            fov_hi = np.asarray(f.attrs["fov_hi"], dtype=float)
            # tracer 0 at frame 0 of the (id, frame) datasets
            x2, x3 = float(f["tracers/x2_true"][0, 0]), float(f["tracers/x3_true"][0, 0])
        frame = np.asarray(Image.open(work / f"{case}.png"), dtype=float)
        # the PNG holds x3 upwards: row 0 is the top of the field of view
        col = int((x2 - fov_lo[-2]) / pixel)
        row = int((fov_hi[-1] - x3) / pixel)
        half = 90
        panels.append((case, frame[row - half : row + half, col - half : col + half]))
    fig, axes = plt.subplots(1, 2, figsize=(7, 3.6), layout="constrained")
    for ax, (case, crop) in zip(axes, panels, strict=True):
        ax.imshow(crop, cmap="gray", vmin=0, vmax=max(crop.max(), 1))
        ax.set_title({"C1": "C1 (air-like)", "C4": "C4 (water-like)"}[case])
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("One tracer through the shipped sample, 180 × 180 px of a 2048 px camera")
    fig.savefig(work / "tracer_images.png", dpi=150)
    save_scaled(work / "tracer_images.png", "tracer_images.png")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        tracer_images(work)
        rimcl("bench", "--quick", "--out", "bench", cwd=work)
        save_scaled(work / "bench" / "bench.png", "bench.png")
        rimcl("study", "--out", "study", "--no-progress", cwd=work)
        for name in ("error_budget", "position_error", "velocity_error"):
            save_scaled(work / "study" / "figures" / f"{name}.png", f"{name}.png")


if __name__ == "__main__":
    main()
