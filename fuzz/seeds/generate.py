"""Write the seed images of the `decode_image` fuzz target: one small textured
image in each format the service decodes, in the variants its decoders take
different paths for (colour and grey, lossy and lossless, compressed and raw).

The files are committed; rerun this only to change them:

    python3 -m venv target/pillow-venv && target/pillow-venv/bin/pip install pillow
    target/pillow-venv/bin/python fuzz/seeds/generate.py

scripts/fuzz.sh adds the curl suite's unusual images (tests/fixtures) to the
corpus as well.
"""

import random
from pathlib import Path

from PIL import Image, ImageDraw

OUT = Path(__file__).resolve().parent / "decode_image"
SIZE = 24


def pattern() -> Image.Image:
    """A grey image of a few seeded shapes: some structure for SIFT to find."""
    rng = random.Random(1)
    img = Image.new("L", (SIZE, SIZE), 128)
    draw = ImageDraw.Draw(img)
    for _ in range(8):
        x, y = rng.randrange(SIZE), rng.randrange(SIZE)
        w, h = rng.randrange(3, 10), rng.randrange(3, 10)
        draw.rectangle([x, y, x + w, y + h], fill=rng.randrange(256))
    return img


def main() -> None:
    OUT.mkdir(exist_ok=True)
    grey = pattern()
    colour = Image.merge("RGB", (grey, grey.rotate(90), grey.rotate(180)))
    grey.save(OUT / "grey.jpg", quality=80)
    colour.save(OUT / "colour-progressive.jpg", quality=80, progressive=True)
    grey.save(OUT / "grey.png")
    colour.convert("P", palette=Image.Palette.ADAPTIVE, colors=16).save(OUT / "palette.png")
    grey.save(OUT / "grey.bmp")
    colour.save(OUT / "colour.bmp")
    colour.convert("P", palette=Image.Palette.ADAPTIVE, colors=16).save(OUT / "palette.bmp")
    grey.save(OUT / "raw.tif")
    colour.save(OUT / "lzw.tif", compression="tiff_lzw")
    grey.save(OUT / "lossy.webp", quality=70)
    colour.save(OUT / "lossless.webp", lossless=True)
    grey.save(OUT / "grey.pgm")
    colour.save(OUT / "colour.ppm")
    grey.convert("1").save(OUT / "bits.pbm")
    # the ASCII forms of PNM, which OpenCV parses number by number
    (OUT / "ascii.pgm").write_text(
        f"P2\n{SIZE} {SIZE}\n255\n" + " ".join(str(v) for v in grey.tobytes()) + "\n"
    )
    (OUT / "ascii.pbm").write_text(
        f"P1\n{SIZE} {SIZE}\n" + " ".join("1" if v < 128 else "0" for v in grey.tobytes()) + "\n"
    )


if __name__ == "__main__":
    main()
