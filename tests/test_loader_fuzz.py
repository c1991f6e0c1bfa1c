"""The image loader against hostile files (issue 14): seeded fuzz cases, header bombs, one limit.

The cases come from ``benchmarks/fuzz_loader.py`` (its seed files of every format the loader
reads and of formats it refuses, and its mutations); here every seed is read as it is and under
each mutation once, a different draw from the benchmark's. Each must load to a finite float
image or raise :class:`InputError` with one line naming the file and saying what to do. Files
whose header claims a huge size must be refused from the header, in a process whose address
space is capped, and valid photos must be read within a small multiple of their size.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from pathlib import Path

import imagecodecs
import numpy as np
import pytest
import tifffile
from PIL import Image

from shadeform.errors import InputError
from shadeform.io.images import (
    MAX_PIXELS,
    MEMORY_NAME,
    ImageTooLargeError,
    load_image,
    load_image_rgb,
    load_mask,
    load_pixels,
    read_photo,
)
from shadeform.photoset import read_photos

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "fuzz_loader.py"
MASTER_SEED = 2002  # not the benchmark's (14): the tests try other files than its table


def _load():
    spec = importlib.util.spec_from_file_location("fuzz_loader", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


fuzz = _load()
SEEDS = fuzz.make_seeds()
SIZE = (28, 36)  # the seeds' height and width
# Past this many pixels the fuzz cases here are refused as too large: a header lying within the
# default limit would otherwise have the test process allocate hundreds of megabytes.
TEST_PIXELS = 2**22


def check_outcome(read, name: str) -> str:
    """Call ``read``; return "" if it loaded a good image or refused it properly, else why not."""
    try:
        image = read()
    except InputError as err:
        message = str(err)
        if "\n" in message or name not in message or "; " not in message:
            return f"bad message: {message!r}"
        return ""
    except Exception as err:  # what this test is about: nothing else may escape
        return f"raw {type(err).__name__}: {err}"
    good = (
        isinstance(image, np.ndarray)
        and image.dtype == np.float32
        and image.ndim == 2
        and min(image.shape) >= 3
        and np.isfinite(image).all()
        and 0.0 <= image.min() <= image.max() <= 1.0
    )
    return "" if good else f"bad result {getattr(image, 'shape', None)} {getattr(image, 'dtype', None)}"


def read_case(case, folder: Path) -> str:
    if case.in_memory:
        return check_outcome(lambda: load_image(case.data, max_pixels=TEST_PIXELS), MEMORY_NAME)
    path = folder / f"case{case.number}.{case.family}"
    path.write_bytes(case.data)
    return check_outcome(lambda: read_photo(path, max_pixels=TEST_PIXELS).image, str(path))


# --- the seeds, unchanged ----------------------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS, ids=[f"{s.family}-{s.name}" for s in SEEDS])
def test_seed(seed, tmp_path):
    path = tmp_path / f"{seed.name}.{seed.family}"
    path.write_bytes(seed.data)
    if not seed.readable:
        with pytest.raises(InputError) as caught:
            read_photo(path)
        message = str(caught.value)
        assert "\n" not in message and str(path) in message and "; " in message, message
        assert not isinstance(caught.value, ImageTooLargeError)
        return
    photo = read_photo(path)
    upright = SIZE[::-1] if "exif-rotated" in seed.name else SIZE
    assert photo.image.shape == upright and photo.image.dtype == np.float32
    assert photo.pixels.shape[:2] == upright and photo.pixels.shape[2] in (1, 3)
    assert np.isfinite(photo.pixels).all() and 0 <= photo.pixels.min() <= photo.pixels.max() <= 1
    assert photo.image.std() > 0.01  # a picture, not a blank


def test_refused_formats_are_named(tmp_path):
    by_name = {s.name: s for s in SEEDS}
    for name, says in (("jpeg2000", "JPEG 2000"), ("avif", "AVIF"), ("psd", "Photoshop"), ("qoi", "QOI")):
        with pytest.raises(InputError, match=f"unsupported image format: .* is in the {says} format"):
            load_image(by_name[name].data)
    with pytest.raises(InputError, match="^not an image: 'image data' is not a PNG, JPEG, TIFF"):
        load_image(by_name["text"].data)


# --- every seed under every mutation, once ----------------------------------------------------


@pytest.mark.parametrize("mutation", fuzz.MUTATIONS)
def test_fuzz(mutation, tmp_path):
    """Cases len(SEEDS) .. 7 len(SEEDS) - 1 are each seed under each mutation (the benchmark's
    numbering); every one must load or be refused with a proper InputError."""
    first = len(SEEDS) * (1 + fuzz.MUTATIONS.index(mutation))
    failures = []
    for number in range(first, first + len(SEEDS)):
        case = fuzz.make_case(number, SEEDS, MASTER_SEED)
        assert case.mutation == mutation
        problem = read_case(case, tmp_path)
        if problem:
            failures.append(f"case {number} {case.family}/{case.seed_name} {case.detail}: {problem}")
    assert not failures, "\n".join(failures)


def test_fuzz_draws_are_reproducible():
    one, two = (fuzz.make_case(4321, SEEDS, MASTER_SEED) for _ in range(2))
    assert one.data == two.data and one.detail == two.detail
    assert fuzz.make_case(4321, SEEDS, MASTER_SEED + 1).data != one.data


# --- bombs: huge sizes claimed by a few bytes ---------------------------------------------------


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bomb(width: int, height: int, depth: int = 8) -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, depth, 2, 0, 0, 0)
    # a valid start of the pixel data: rows of zeros, deflated
    idat = zlib.compress(b"\x00" * 65536, 9)
    return (
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")
    )


def jpeg_bomb(width: int, height: int, **options) -> bytes:
    """A small valid JPEG whose frame header is rewritten to claim ``width`` x ``height``
    (the audit's bomb: a 2.6 KB file claiming 9000x9000)."""
    data = bytearray(fuzz._pil(Image.fromarray(fuzz._picture()), "JPEG", **options))
    at = fuzz._jpeg_sof(bytes(data))
    data[at + 3 : at + 7] = struct.pack(">HH", height, width)
    return bytes(data)


def tiff_bomb(width: int, height: int, **options) -> bytes:
    data = fuzz._tiff(fuzz._picture(channels=1), **options)
    out = bytearray(data)
    (ifd,) = struct.unpack("<I", out[4:8])
    (count,) = struct.unpack("<H", out[ifd : ifd + 2])
    for k in range(count):
        at = ifd + 2 + 12 * k
        tag, kind = struct.unpack("<HH", out[at : at + 4])
        value = {256: width, 257: height}.get(tag)
        if value is not None:
            out[at + 8 : at + 12] = (
                struct.pack("<H", value) + b"\0\0" if kind == 3 else struct.pack("<I", value)
            )
    return bytes(out)


def gif_bomb(width: int, height: int) -> bytes:
    data = bytearray(fuzz._pil(Image.fromarray(fuzz._picture()).quantize(16), "GIF"))
    data[6:10] = struct.pack("<HH", width, height)  # the logical screen
    return bytes(data)


def bmp_bomb(width: int, height: int) -> bytes:
    data = bytearray(fuzz._pil(Image.fromarray(fuzz._picture()), "BMP"))
    data[18:26] = struct.pack("<ii", width, height)
    return bytes(data)


def webp_bomb(width: int, height: int) -> bytes:
    """A lossy WebP with an extended header (VP8X) claiming a huge canvas."""
    frame = fuzz._pil(Image.fromarray(fuzz._picture()), "WEBP", quality=80)[12:]  # the VP8 chunk
    vp8x = b"VP8X" + struct.pack("<I", 10) + b"\0\0\0\0"
    vp8x += (width - 1).to_bytes(3, "little") + (height - 1).to_bytes(3, "little")
    body = b"WEBP" + vp8x + frame
    return b"RIFF" + struct.pack("<I", len(body)) + body


# Each claims more than MAX_PIXELS in a file of a few kilobytes.
BOMBS = {
    "png-9000": lambda: png_bomb(9000, 9000),
    "png16-100000": lambda: png_bomb(100_000, 100_000, depth=16),
    "jpeg-9000": lambda: jpeg_bomb(9000, 9000),
    "jpeg-progressive-9000": lambda: jpeg_bomb(9000, 9000, progressive=True),
    "jpeg-65535": lambda: jpeg_bomb(65535, 65535),
    "tiff-60000": lambda: tiff_bomb(60000, 60000),
    "tiff-lzw-60000": lambda: tiff_bomb(60000, 60000, compression="lzw"),
    "tiff-tiled-60000": lambda: tiff_bomb(60000, 60000, tile=(16, 16)),
    "gif-65535": lambda: gif_bomb(65535, 65535),
    "bmp-30000": lambda: bmp_bomb(30000, 30000),
    "bmp-top-down-30000": lambda: bmp_bomb(30000, -30000),
    "webp-16384": lambda: webp_bomb(16384, 16384),
    "pnm-100000": lambda: b"P6\n100000 100000\n255\n" + bytes(3000),
}


@pytest.mark.parametrize("name", list(BOMBS))
def test_bomb_refused_from_the_header(name, tmp_path):
    path = tmp_path / f"{name}.img"
    path.write_bytes(BOMBS[name]())
    assert path.stat().st_size < 20_000
    with pytest.raises(
        ImageTooLargeError, match=f"image too large: '{path}' declares .*max_pixels"
    ) as caught:
        read_photo(path)
    assert "\n" not in str(caught.value)


# Within the limit, or with the limit raised, the files still cannot hold what they claim: the
# check of their data against the declared size refuses them, also before decoding.
SHORT = {
    "png-8000": lambda: png_bomb(8000, 8000),
    "png16-8000": lambda: png_bomb(8000, 8000, depth=16),
    "jpeg-8000": lambda: jpeg_bomb(8000, 8000),
    "jpeg-progressive-8000": lambda: jpeg_bomb(8000, 8000, progressive=True),
    "tiff-8000": lambda: tiff_bomb(8000, 8000),
    "gif-8000": lambda: gif_bomb(8000, 8000),
    "bmp-8000": lambda: bmp_bomb(8000, 8000),
    "webp-8000": lambda: webp_bomb(8000, 8000),
}

_MEASURE = textwrap.dedent(
    """
    import json, resource, sys
    from pathlib import Path
    from shadeform.errors import InputError
    from shadeform.io.images import read_photo

    def kib(key):
        for line in open("/proc/self/status"):
            if line.startswith(key + ":"):
                return int(line.split()[1])

    read_photo(sys.argv[1])  # every decoder's lazy imports, before the cap
    cap = kib("VmSize") * 1024 + int(sys.argv[2]) * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    out = {}
    for arg in sys.argv[3:]:
        path, limit = arg.rsplit("@", 1)
        open("/proc/self/clear_refs", "w").write("5")  # resets the peak (VmHWM)
        before = kib("VmRSS")
        photo = None
        try:
            photo = read_photo(path, max_pixels=int(limit))
            outcome = ["loaded", photo.pixels.nbytes + photo.image.nbytes]
        except InputError as err:
            outcome = [type(err).__name__, str(err)]
        except MemoryError:
            outcome = ["MemoryError", ""]
        out[arg] = outcome + [(kib("VmHWM") - before) / 1024]
        photo = None
    print(json.dumps(out))
    """
)


def measure(paths_and_limits, tmp_path, headroom_mib: int = 1024) -> dict:
    """Read each ``path@max_pixels`` in a fresh process whose address space may grow only
    ``headroom_mib`` past what it holds after warming up; return outcome, detail and peak MiB."""
    warm = tmp_path / "warm.png"
    Image.fromarray(fuzz._picture()).save(warm)
    env = {**os.environ, "MALLOC_MMAP_THRESHOLD_": "131072", "OPENBLAS_NUM_THREADS": "1"}
    args = [f"{path}@{limit}" for path, limit in paths_and_limits]
    done = subprocess.run(
        [sys.executable, "-c", _MEASURE, str(warm), str(headroom_mib), *args],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


LINUX_MEMORY = pytest.mark.skipif(
    not Path("/proc/self/clear_refs").exists(), reason="measures memory through Linux's /proc"
)


@LINUX_MEMORY
def test_bombs_allocate_nothing(tmp_path):
    """In a process that may allocate only 256 MiB more, each bomb is refused (as too large by
    default; as not holding its claimed size with max_pixels raised to 10**12), and no refusal
    grows the process by more than 16 MiB."""
    runs = []
    for name, make in {**BOMBS, **SHORT}.items():
        path = tmp_path / f"{name}.img"
        path.write_bytes(make())
        runs += [(path, MAX_PIXELS), (path, 10**12)]
    found = measure(runs, tmp_path, headroom_mib=256)
    for (path, limit), (outcome, detail, peak) in zip(runs, found.values()):
        assert outcome in ("InputError", "ImageTooLargeError"), (path.name, limit, outcome, detail)
        if limit == 10**12:
            assert outcome == "InputError", (path.name, detail)
            assert "cannot hold" in detail or "holds only" in detail or "fills only" in detail, detail
        assert peak < 16, (path.name, limit, peak)


@LINUX_MEMORY
def test_valid_photos_cost_a_small_multiple_of_their_size(tmp_path):
    """Peak memory of reading a 1500x1000 photo: at most the file, its samples and 1.25 times
    the result (float32 pixels and the channel solved on), plus 16 MiB."""
    height, width = 1000, 1500
    rgb, rgb16 = fuzz._picture(height, width), fuzz._picture(height, width, dtype=np.uint16)
    image = Image.fromarray(rgb)
    files = {
        "rgb.jpg": (fuzz._pil(image, "JPEG", quality=90), 3),
        "rgb16.png": (imagecodecs.png_encode(rgb16, level=1), 6),
        "rgb-lzw.tif": (fuzz._tiff(rgb, photometric="rgb", compression="lzw"), 3),
        "palette.gif": (fuzz._pil(image.quantize(256), "GIF"), 1),
        "gray16.tif": (fuzz._tiff(rgb16[:, :, 0], compression="zlib"), 2),
    }
    for name, (data, _) in files.items():
        (tmp_path / name).write_bytes(data)
    found = measure([(tmp_path / name, MAX_PIXELS) for name in files], tmp_path)
    for (name, (data, sample_bytes)), (outcome, result, peak) in zip(files.items(), found.values()):
        assert outcome == "loaded", (name, result)
        real = height * width * sample_bytes
        allowed = (len(data) + real + 1.25 * result) / 2**20 + 16
        assert peak <= allowed, (name, peak, allowed)


# --- work bounded by the file's structure -----------------------------------------------------


def seed_data(name: str) -> bytes:
    return next(s.data for s in SEEDS if s.name == name)


def gif_flood(count: int) -> bytes:
    data = seed_data("still")
    at = 13 + (3 << ((data[10] & 7) + 1) if data[10] & 0x80 else 0)
    return data[:at] + b"\x21\xfe" + b"\x01a" * count + b"\x00" + data[at:]


# Headers that Pillow would walk in Python an element at a time, for many seconds.
FLOODS = {
    "png": (
        lambda: seed_data("gray8")[:33] + png_chunk(b"tEXt", b"a\x00b") * 40_000 + seed_data("gray8")[33:],
        "chunks",
    ),
    "jpeg": (
        lambda: seed_data("gray")[:2] + b"\xff\xfe\x00\x02" * 20_000 + seed_data("gray")[2:],
        "segments",
    ),
    "jpeg-stray": (
        lambda: seed_data("gray")[:2] + b"\x00" * 2_000_000 + seed_data("gray")[2:],
        "stray bytes",
    ),
    "gif": (lambda: gif_flood(200_000), "extension blocks"),
    "pnm": (lambda: b"P5\n#" + b"x" * 100_000 + b"\n36 28\n255\n" + bytes(1008), "no complete header"),
}


@pytest.mark.parametrize("name", list(FLOODS))
def test_flooded_headers_are_refused_at_once(name):
    make, says = FLOODS[name]
    data = make()
    start = time.perf_counter()
    with pytest.raises(InputError, match=f"truncated or damaged .*{says}"):
        load_image(data)
    assert time.perf_counter() - start < 1.0


def test_a_few_floods_still_load():
    """Real files have tens of header elements: a few hundred more are still read."""
    assert load_image(seed_data("gray")[:2] + b"\xff\xfe\x00\x02" * 300 + seed_data("gray")[2:]).shape == SIZE
    assert load_image(gif_flood(5000)).shape == SIZE


def rle_bmp_claiming(width: int, height: int) -> bytes:
    """An 8-bit run-length BMP that ends its bitmap at once."""
    palette = b"".join(bytes([i, i, i, 0]) for i in range(256))
    body = b"\x00\x01"
    offset = 14 + 40 + len(palette)
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 8, 1, len(body), 2835, 2835, 256, 0)
    return b"BM" + struct.pack("<IHHI", offset + len(body), 0, 0, offset) + info + palette + body


def test_slow_formats_are_capped():
    """Pillow decodes run-length BMP and plain-text PNM in Python: past 4 Mpx they are refused
    (a 2-byte run-length bitmap may claim any size; ending each row costs a Python step a pixel)."""
    start = time.perf_counter()
    with pytest.raises(InputError, match="is a run-length compressed BMP of 3000x3000 pixels"):
        load_image(rle_bmp_claiming(3000, 3000))
    text = b"P2\n3000 3000\n255\n" + b"0 " * (3000 * 3000)
    with pytest.raises(InputError, match="is a plain-text PBM/PGM/PPM of 3000x3000 pixels"):
        load_image(text)
    assert time.perf_counter() - start < 1.0
    assert load_image(seed_data("rle8")).shape == SIZE


def test_pgm_of_another_largest_value():
    """12-bit data in a 16-bit PGM (largest value 4095): read against 4095, linear, at once."""
    values = np.random.default_rng(3).integers(0, 4096, (300, 400)).astype(">u2")
    photo = read_photo(b"P5\n400 300\n4095\n" + values.tobytes())
    assert photo.bits == 16 and photo.encoding == "linear"
    np.testing.assert_array_equal(photo.image, values.astype(np.float32) / np.float32(4095))


# --- the one pixel limit ------------------------------------------------------------------------


READERS = {
    "read_photo": lambda source, **kw: read_photo(source, **kw).image,
    "load_image": load_image,
    "load_pixels": load_pixels,
    "load_image_rgb": load_image_rgb,
    "load_mask": load_mask,
    "read_photos": lambda source, **kw: read_photos([source, source, source], **kw)[0],
}
ONE_PER_FORMAT = [
    s
    for s in SEEDS
    if s.readable and s.name in ("rgb8", "baseline", "gray16", "rgb24", "still", "lossy", "ppm")
]


@pytest.mark.parametrize("reader", list(READERS))
@pytest.mark.parametrize("seed", ONE_PER_FORMAT, ids=[f"{s.family}-{s.name}" for s in ONE_PER_FORMAT])
def test_max_pixels_raises_and_lowers_the_limit(reader, seed, tmp_path):
    path = tmp_path / f"{seed.name}.{seed.family}"
    path.write_bytes(seed.data)
    pixels = SIZE[0] * SIZE[1]
    with pytest.raises(ImageTooLargeError, match=f"max_pixels={pixels - 1:,}"):
        READERS[reader](path, max_pixels=pixels - 1)
    assert READERS[reader](path, max_pixels=pixels).shape[-3 if reader == "read_photos" else 0] > 0


@pytest.mark.parametrize("make", [png_bomb, tiff_bomb, bmp_bomb], ids=["png", "tiff", "bmp"])
def test_default_limit_is_max_pixels(make, tmp_path):
    """One pixel past MAX_PIXELS is refused by default; raising max_pixels lets the header pass
    (the file, which holds no such picture, is then refused as damaged)."""
    path = tmp_path / "big.img"
    path.write_bytes(make(8192, 8193))
    with pytest.raises(ImageTooLargeError, match=f"max_pixels={MAX_PIXELS:,}"):
        load_image(path)
    with pytest.raises(InputError, match="truncated or damaged") as caught:
        load_image(path, max_pixels=8192 * 8193)
    assert not isinstance(caught.value, ImageTooLargeError)


def test_file_size_is_capped_before_reading(tmp_path):
    path = tmp_path / "huge.png"
    with open(path, "wb") as fh:
        fh.truncate(100 * 2**20)  # sparse: 100 MiB that take no disk
    with pytest.raises(ImageTooLargeError, match="file too large: .* 104,857,600 bytes"):
        load_image(path, max_pixels=1000)


@pytest.mark.parametrize("bad", [0, -5, 2.5, "100", True, None])
def test_max_pixels_must_be_a_positive_whole_number(bad):
    with pytest.raises(InputError, match="max_pixels must be a positive whole number"):
        load_image(SEEDS[0].data, max_pixels=bad)


# --- files that are not files -------------------------------------------------------------------


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_pipe_is_refused_without_reading(tmp_path):
    pipe = tmp_path / "photo.png"
    os.mkfifo(pipe)  # reading it would block for ever
    with pytest.raises(InputError, match="not a file"):
        load_image(pipe)


def test_unreadable_name(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_image(str(tmp_path / "a\0b.png"))


def test_tiff_tags_of_the_wrong_kind(tmp_path):
    """A tile width held as two numbers (tifffile hands back a tuple) is a damaged file."""
    values = fuzz._picture()
    data = io.BytesIO()
    tifffile.imwrite(data, values, photometric="rgb", tile=(16, 16))
    raw = bytearray(data.getvalue())
    (ifd,) = struct.unpack("<I", raw[4:8])
    (count,) = struct.unpack("<H", raw[ifd : ifd + 2])
    for k in range(count):
        at = ifd + 2 + 12 * k
        if struct.unpack("<H", raw[at : at + 2])[0] == 322:  # TileWidth: SHORT, 2 values
            raw[at + 2 : at + 8] = struct.pack("<HI", 3, 2)
            raw[at + 8 : at + 12] = struct.pack("<HH", 16, 16)
    with pytest.raises(InputError, match="truncated or damaged TIFF: 'image data'"):
        load_image(bytes(raw))
