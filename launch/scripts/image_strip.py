#!/usr/bin/env python3
"""Composes frames written by render_states (PPM) into one PNG strip with a time label under
each frame: image_strip.py OUT.png "caption" t0:frame0.ppm t1:frame1.ppm ..."""
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read_ppm(path):
    with open(path, "rb") as f:
        data = f.read()
    fields, pos = [], 0
    while len(fields) < 4:  # magic, width, height, maxval; whitespace separated
        while data[pos:pos + 1].isspace():
            pos += 1
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    if fields[0] != b"P6" or fields[3] != b"255":
        raise ValueError(f"{path}: not an 8-bit binary PPM")
    width, height = int(fields[1]), int(fields[2])
    pixels = np.frombuffer(data, dtype=np.uint8, count=3 * width * height, offset=pos + 1)
    return pixels.reshape(height, width, 3)


def main(argv):
    if len(argv) < 4:
        sys.exit(__doc__)
    out, caption, frames = argv[1], argv[2], []
    for item in argv[3:]:
        time, _, path = item.partition(":")
        frames.append((float(time), read_ppm(path)))
    height, width, _ = frames[0][1].shape
    fig, axes = plt.subplots(1, len(frames), figsize=(2.4 * len(frames), 2.4 * height / width + 0.6))
    for ax, (time, image) in zip(np.atleast_1d(axes), frames):
        ax.imshow(image)
        ax.set_axis_off()
        ax.set_title(f"t = {time:.2f} s", fontsize=9)
    fig.suptitle(caption, fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"image_strip: wrote {out}")


if __name__ == "__main__":
    main(sys.argv)
