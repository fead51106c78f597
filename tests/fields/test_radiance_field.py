"""Source radiance fields: sampling, reduction, the srf asset and lookup, against ray tracing."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.data_formats.srf import read_radiance_field, write_radiance_field
from shtools.errors import AssetError, InputError
from shtools.fields import FieldParameters
from shtools.fields.emitter import make_emitter
from shtools.fields.radiance import emitter_sphere, sample_radiance_field, sample_rcvs
from shtools.fields.reduction import l1_error
from shtools.geometry.raycast import RayCaster
from shtools.reference import relative_rmse
from shtools.reference.emitter import emitter_radiance, shaded_lamp
from shtools.runtime import SphereLight
from shtools.runtime.radiance import FieldLight, field_light_radiance
from shtools.runtime.shading import sphere_light_sh

RADIANCE = (10.0, 9.0, 8.0)


@pytest.fixture(scope="module")
def lamp():
    bulb, shade = shaded_lamp()
    return make_emitter(bulb, RADIANCE, [shade])


@pytest.fixture(scope="module")
def lamp_field(lamp):
    # 32 shells as the paper, coarse grids so the test stays quick (~1 M rays)
    params = FieldParameters(shells=32, resolution=16, map_size=12, order=4, min_resolution=4)
    return sample_radiance_field(lamp, params, scheduler="inline")


def _ground(n=13, size=2.4, z=-1.2):
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs)
    pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)]
    return pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1))


def _rot_x(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def test_rcv_of_a_bare_bulb_is_the_closed_form_sphere_light():
    bulb = trimesh.creation.icosphere(4, radius=0.2)
    em = make_emitter(bulb, (1.0, 2.0, 0.5))
    pts = np.array([[0.0, 0.0, -1.0], [0.7, 0.3, 0.4], [0.0, -0.5, 0.1], [0.05, 0.0, 0.1]])
    c, r = emitter_sphere(em)
    rcv = sample_rcvs(RayCaster(em.vertices, em.faces), em, c, r, pts, 32, 4)
    exact = sphere_light_sh(SphereLight(c, 0.2, (1, 1, 1)), pts, 4)  # closed-form cap SH
    for ch, L in enumerate((1.0, 2.0, 0.5)):
        # the icosphere (level 4) is inscribed in the radius-0.2 sphere: its silhouette
        # is ~0.1 % smaller, and the 32 x 32 cone cells cut its edge: well under 2 %
        # of the DC term; the last point is inside the bulb (sees nothing: it faces back)
        np.testing.assert_allclose(rcv[:3, ch], L * exact[:3], atol=0.02 * L * exact[0, 0])
    assert np.abs(rcv[3]).max() < 1e-12


def test_the_reference_is_the_closed_form_sphere_irradiance():
    bulb = trimesh.creation.icosphere(4, radius=0.13)
    em = make_emitter(bulb, (1.0, 1.0, 1.0))
    pts = np.array([[0, 0, -1.2], [0.5, 0, -1.2], [1.2, 0, -1.2]], dtype=float)
    nrm = np.tile([0, 0, 1.0], (3, 1))
    ref = emitter_radiance(pts, nrm, em.vertices, em.faces, em.emissive, em.radiance, [],
                           n_samples=20000)
    d = np.linalg.norm(pts, axis=1)
    closed = (0.13 / d) ** 2 * 1.2 / d  # L sin^2(a) cos(t): the whole cap above the horizon
    # 20000 area samples of a smooth integrand: Monte Carlo ~0.5 %, faceting ~0.1 %
    np.testing.assert_allclose(ref[:, 0], closed, rtol=0.015)


def test_l1_error_of_rgb_is_the_worst_channel():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(2, 5, 3 * 16))
    per = [l1_error(a[:, k * 16:(k + 1) * 16], b[:, k * 16:(k + 1) * 16]) for k in range(3)]
    np.testing.assert_allclose(l1_error(a, b, channels=3), np.max(per, axis=0), rtol=1e-12)


def test_field_light_matches_the_raytraced_emitter_while_moving(lamp, lamp_field):
    fld, _ = lamp_field
    pts, nrm = _ground()
    free = np.zeros((len(pts), 16))
    free[:, 0] = math.sqrt(4 * math.pi)
    for tx, deg in ((0.0, 0.0), (0.3, 20.0), (-0.4, -35.0)):
        R, t = _rot_x(deg), np.array([tx, 0.0, 0.0])
        light = FieldLight(fld, R, t)
        got = field_light_radiance(light, free, pts, nrm, order=4, window_kind=None)
        ref = emitter_radiance(pts, nrm, lamp.vertices @ R.T + t, lamp.faces, lamp.emissive,
                               lamp.radiance, [], n_samples=8192)
        # order-4 SH of a 6-degree bulb cut by its shade: the truncation alone is ~3.5 %
        # (RCVs projected at the receivers themselves), the 16 x 16 shells' interpolation
        # adds to it (4.6-5.0 % in all); 8192 area samples add < 1 % of noise
        assert relative_rmse(got, ref) < 0.065


def test_rotating_lamp_and_receivers_together_changes_nothing(lamp_field):
    fld, _ = lamp_field
    pts, nrm = _ground(7)
    free = np.zeros((len(pts), 16))
    free[:, 0] = math.sqrt(4 * math.pi)
    base = field_light_radiance(FieldLight(fld), free, pts, nrm, order=4)
    R = trimesh.transformations.rotation_matrix(0.7, [0.3, 1.0, -0.2])[:3, :3]
    t = np.array([0.5, -2.0, 1.0])
    moved = field_light_radiance(FieldLight(fld, R, t, scale=1.0), free, pts @ R.T + t,
                                 nrm @ R.T, order=4)
    # SH rotation is exact; only float32 lookup round-off differs
    np.testing.assert_allclose(moved, base, rtol=1e-3, atol=1e-6 * base.max())


def test_asset_round_trip_and_lookup_at_samples(tmp_path, lamp_field):
    fld, _ = lamp_field
    path = write_radiance_field(tmp_path / "lamp.srf.h5", fld)
    back = read_radiance_field(path)
    assert back.resolution.tolist() == fld.resolution.tolist()
    c = 20
    R = int(back.resolution[c])
    s, u = 3, 5  # a sample's own position on shell c: the lookup returns it
    theta, phi = (s + 0.5) * math.pi / R, (u + 0.5) * 2 * math.pi / R
    p = back.center + back.shell_radii[c] * np.array(
        [math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
    got = FieldLight(back).table.radiance_lookup(p[None])[0].reshape(-1)
    want = back.offset[c] + back.rcv[c][s, u].astype(np.float32) * back.step[c]
    np.testing.assert_allclose(got, want, atol=1e-5 * np.abs(want).max())


def test_beyond_the_last_shell_falls_off_as_the_inverse_square(lamp_field):
    fld, _ = lamp_field
    table = FieldLight(fld).table
    direction = np.array([0.3, -0.2, -0.93])
    direction /= np.linalg.norm(direction)
    r_last = table.radii[-1]
    near = table.radiance_lookup(table.center + r_last * direction[None])
    far = table.radiance_lookup(table.center + 3 * r_last * direction[None])
    np.testing.assert_allclose(far, near / 9, rtol=1e-5, atol=1e-9)


def test_bad_emitters_are_refused(tmp_path):
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    with pytest.raises(InputError, match="emits nothing"):
        make_emitter(box, (0.0, 0.0, 0.0))
    quad = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    with pytest.raises(InputError, match="the emitter is open"):
        make_emitter(quad, (1.0, 1.0, 1.0))
    inward = box.copy()
    inward.invert()
    with pytest.raises(InputError, match="point inward"):
        make_emitter(inward, (1.0, 1.0, 1.0))


def test_srf_asset_checks_its_shapes(tmp_path, lamp_field):
    import h5py

    fld, _ = lamp_field
    path = write_radiance_field(tmp_path / "lamp.srf.h5", fld)
    with h5py.File(path, "r+") as f:
        del f["shells/3/step"]
    with pytest.raises(AssetError, match="shells/3/step"):
        read_radiance_field(path)


# ---------------------------------------------------------------- the CLI stage
SMALL = ("--shells", 4, "--resolution", 8, "--map", 8, "--order", 3, "--min-resolution", 2)


@pytest.fixture
def lamp_files(tmp_path):
    bulb, shade = shaded_lamp(subdivisions=1, sections=16)
    bulb.export(tmp_path / "bulb.obj")
    shade.export(tmp_path / "shade.obj")
    (tmp_path / "lamp.toml").write_text('radiance = [4.0, 3.0, 2.0]\nfixture = ["shade.obj"]\n')
    return tmp_path


def test_cli_samples_an_srf_asset(run_cli, lamp_files):
    import json

    d = lamp_files
    out = d / "lamp.srf.h5"
    code, stdout, err = run_cli("field", "sample", d / "bulb.obj", "--radiance", d / "lamp.toml",
                                "-o", out, *SMALL, "--scheduler", "inline", "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    fld = read_radiance_field(out)
    assert summary["bytes"] == sum(int(r) ** 2 for r in fld.resolution) * 3 * 9
    assert fld.radiance.tolist() == [4.0, 3.0, 2.0] and fld.attrs["fixture_faces"] == 32
    first = out.read_bytes()
    out.unlink()
    code, _, err = run_cli("field", "sample", d / "bulb.obj", "--radiance", d / "lamp.toml",
                           "-o", out, *SMALL, "--scheduler", "inline")
    assert code == 0, err
    assert out.read_bytes() == first  # deterministic bytes


@pytest.mark.parametrize("table, needle", [
    ("radiance = [0, 0, 0]\n", "emits nothing"),
    ("radiance = [1, 1]\n", "three numbers"),
    ("radiance = [1, 1, 1]\ncolour = 2\n", "unknown key 'colour'"),
    ('radiance = [1, 1, 1]\nfixture = ["missing.obj"]\n', "not found"),
    ("fixture = []\n", "missing key 'radiance'"),
    ("radiance = [1, 1, 1\n", "not a valid TOML"),
])
def test_cli_bad_emission_one_line_no_file(run_cli, lamp_files, table, needle):
    d = lamp_files
    (d / "bad.toml").write_text(table)
    out = d / "x.srf.h5"
    code, _, err = run_cli("field", "sample", d / "bulb.obj", "--radiance", d / "bad.toml",
                           "-o", out, *SMALL)
    assert code not in (0, 3) and needle in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_cli_refuses_an_open_emitter(run_cli, lamp_files):
    d = lamp_files
    out = d / "x.srf.h5"
    code, _, err = run_cli("field", "sample", d / "shade.obj", "--radiance", d / "lamp.toml",
                           "-o", out, *SMALL)
    assert code not in (0, 3) and "the emitter is open" in err, err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


# ---------------------------------------------------------------- the error scale
def test_receiver_weights_are_the_clamped_cosine_bands():
    from scipy.integrate import quad
    from scipy.special import eval_legendre

    from shtools.fields.radiance import receiver_weights

    n = 6
    w = receiver_weights(n)
    for band in range(n):
        # Funk-Hecke: convolving with max(0, cos)/pi scales band l by 2 int_0^1 t P_l(t) dt
        lam = abs(2 * quad(lambda t, b=band: t * eval_legendre(b, t), 0, 1)[0])
        if band >= 3 and band % 2:
            assert lam < 1e-12  # the clamped cosine has no odd band above 1 ...
            lam = abs(2 * quad(lambda t, b=band - 1: t * eval_legendre(b, t), 0, 1)[0])
        # ... where the scale takes the band below's (a shadowed transfer has it)
        np.testing.assert_allclose(w[band * band:(band + 1) ** 2], lam, rtol=1e-10)


def test_each_scale_stores_the_sampled_rcvs_box_averaged(lamp):
    from shtools.fields.radiance import build_radiance_field, sample_radiance_shells
    from shtools.fields.reduction import box2

    params = FieldParameters(shells=6, resolution=16, map_size=8, order=4, min_resolution=2)
    sampled = sample_radiance_shells(lamp, params, scheduler="inline")
    sizes = {}
    for scale in ("receiver", "peak", "emitter"):
        fld, _ = build_radiance_field(sampled, lamp, params, error_scale=scale)
        sizes[scale] = fld.stored_bytes()
        for c in range(params.shells):
            want = sampled.grids[c]
            while want.shape[0] > fld.resolution[c]:
                want = box2(want)
            got = fld.offset[c] + fld.rcv[c].astype(np.float64) * fld.step[c]
            # 8-bit quantization: within half a step of the box average
            assert np.all(np.abs(got - want) <= 0.5 * fld.step[c] + 1e-6 * np.abs(want).max())
    # the receiver scale ignores the band-3 ringing no Lambertian receiver sees: it
    # keeps no more samples than the raw peak scale, and the absolute emitter scale
    # (the lamp's coverage, tiny far away) the fewest
    assert sizes["emitter"] <= sizes["receiver"] <= sizes["peak"]
