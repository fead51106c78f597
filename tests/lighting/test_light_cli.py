"""``shtools light project``: round trip through real image files, and bad images."""

from __future__ import annotations

import json

import numpy as np
import pytest

from shtools.data_formats import sha256_file
from shtools.data_formats.light import read_light
from shtools.errors import InputError
from shtools.lighting import load_hdr_image, project_latlong


def write_pfm(path, rgb):
    """Portable float map, written by hand (rows bottom to top, little-endian)."""
    rgb = np.asarray(rgb, dtype="<f4")
    height, width, _ = rgb.shape
    with open(path, "wb") as fh:
        fh.write(f"PF\n{width} {height}\n-1.0\n".encode())
        fh.write(np.ascontiguousarray(rgb[::-1]).tobytes())
    return path


def write_hdr(path, rgb):
    """Radiance RGBE via OpenCV (BGR order)."""
    import cv2

    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1], dtype=np.float32))
    return path


def sky_image(height=16):
    """Values exactly representable in RGBE (8-bit mantissa): 0.5, 1, 3."""
    image = np.empty((height, 2 * height, 3), np.float32)
    image[...] = (0.5, 1.0, 3.0)
    image[: height // 4] = (3.0, 3.0, 1.0)  # a bright cap about +y
    return image


@pytest.mark.parametrize("writer", [write_pfm, write_hdr], ids=["pfm", "hdr"])
def test_loader_returns_rgb_in_row_order(tmp_path, writer):
    image = sky_image()
    image[0, 0] = (1.0, 0.5, 0.0)  # top-left pixel: tells rows and channels apart
    path = writer(tmp_path / f"sky.{writer.__name__[-3:]}", image)
    np.testing.assert_array_equal(load_hdr_image(path), image)


def test_cli_projects_and_records_provenance(run_cli, tmp_path):
    image = sky_image()
    src = write_hdr(tmp_path / "sky.hdr", image)
    out = tmp_path / "light.h5"
    code, stdout, stderr = run_cli("light", "project", src, "--order", 4, "-o", out,
                                   "--exposure", 1, "--rotate-y", 30, "--json")
    assert code == 0, stderr
    coeffs, attrs = read_light(out)
    assert coeffs.shape == (16, 3) and attrs["source"] == "image"
    from shtools.lighting import environment_rotation

    expected = 2.0 * project_latlong(image, 4, rotation=environment_rotation(30.0))
    np.testing.assert_allclose(coeffs, expected, rtol=1e-12, atol=1e-12)
    assert attrs["inputs"] == {"sky.hdr": sha256_file(src)}
    assert attrs["parameters"]["exposure_ev"] == 1.0
    assert attrs["parameters"]["rotate_y_degrees"] == 30.0
    summary = json.loads(stdout)
    # the bright cap is about +y, so the light comes mostly from above
    assert summary["brightest_direction"][1] > 0.99


def test_cli_window_multiplies_each_band(run_cli, tmp_path):
    """Cosine window: band l scaled by cos(pi/2 * l/h), formula written out here."""
    src = write_hdr(tmp_path / "sky.hdr", sky_image())
    plain, windowed = tmp_path / "a.h5", tmp_path / "b.h5"
    assert run_cli("light", "project", src, "-n", 5, "-o", plain)[0] == 0
    assert run_cli("light", "project", src, "-n", 5, "-o", windowed, "--window", "cosine",
                   "--window-h", 6)[0] == 0
    a, b = read_light(plain)[0], read_light(windowed)[0]
    l = np.repeat(np.arange(5), 2 * np.arange(5) + 1)
    np.testing.assert_allclose(b, a * np.cos(np.pi / 2 * l / 6)[:, None], rtol=1e-14,
                               atol=1e-15)


@pytest.mark.parametrize(
    ("name", "make", "message"),
    [
        ("nan.pfm", lambda p: write_pfm(p, np.where(np.arange(3) == 1, np.nan,
                                                     sky_image())), "NaN or inf"),
        ("inf.pfm", lambda p: write_pfm(p, np.where(sky_image() > 2, np.inf, 1.0)),
         "NaN or inf"),
        ("negative.pfm", lambda p: write_pfm(p, sky_image() - 0.75), "pixels are negative"),
        ("square.hdr", lambda p: write_hdr(p, np.ones((16, 16, 3))), "angular-map"),
        ("wide.hdr", lambda p: write_hdr(p, np.ones((8, 24, 3))), "twice as wide as high"),
        ("garbage.hdr", lambda p: p.write_bytes(b"#?RADIANCE\nnonsense"), "cannot decode"),
        ("photo.png", lambda p: p.write_bytes(b"\x89PNG"), "unsupported image type"),
        ("missing.hdr", lambda p: None, "image not found"),
    ],
)
def test_cli_bad_images_give_one_line_errors(run_cli, tmp_path, name, make, message):
    src = tmp_path / name
    make(src)
    out = tmp_path / "light.h5"
    code, stdout, stderr = run_cli("light", "project", src, "--order", 3, "-o", out)
    assert code == 1 and stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith(f"error: {src}: ")
    assert message in stderr
    assert not out.exists()


def write_exr(path, rgb, dtype=np.float32, channels="RGB"):
    """OpenEXR with separate channels, written with the OpenEXR bindings."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    data = {c: np.ascontiguousarray(rgb[..., i], dtype=dtype) for i, c in enumerate(channels)}
    with OpenEXR.File(header, data) as exr:
        exr.write(str(path))
    return path


@pytest.mark.parametrize("dtype", [np.float16, np.float32])
def test_exr_loads_as_rgb_in_row_order(tmp_path, dtype):
    image = sky_image()
    image[0, 0] = (1.0, 0.5, 0.0)
    path = write_exr(tmp_path / "sky.exr", image, dtype)
    np.testing.assert_array_equal(load_hdr_image(path), image)  # all values exact in half


def test_cli_projects_an_exr_like_the_same_hdr(run_cli, tmp_path):
    image = sky_image()
    outs = []
    for path in (write_exr(tmp_path / "sky.exr", image), write_hdr(tmp_path / "sky.hdr", image)):
        outs.append(tmp_path / f"{path.suffix[1:]}.h5")
        assert run_cli("light", "project", path, "-n", 3, "-o", outs[-1])[0] == 0
    code, stdout, _ = run_cli("diff", *outs, "--rtol", 1e-12)
    assert code == 0, stdout


def test_exr_errors(tmp_path):
    grey = write_exr(tmp_path / "grey.exr", sky_image()[..., :1], channels="Y")
    with pytest.raises(InputError, match=r"no R/G/B channel \(channels: Y\)"):
        load_hdr_image(grey)
    broken = tmp_path / "broken.exr"
    broken.write_bytes(b"v/1\x01" + bytes(60))  # OpenEXR magic, no valid header
    with pytest.raises(InputError, match=r"cannot decode the image as \.exr"):
        load_hdr_image(broken)
