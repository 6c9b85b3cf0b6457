"""Star-camera attitude (SCA1B) reader and the rotations inertial <-> SRF.

Values are written out by hand from the raw text of the real sample files in
``data/samples/`` (see PROVENANCE.md); the line each one comes from is quoted.
"""

import gzip
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.errors import AccalError, FormatError, UnsupportedFormatError, ValidationError
from accal.io.attitude import (
    DEFAULT_MAX_GAP,
    NORM_TOLERANCE,
    Attitude,
    continuous_quaternions,
    find_attitude_file,
    read_attitude,
    rotate_to_inertial,
    rotate_to_srf,
)
from accal.timescale import gps_to_utc

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
SCA = {
    "A": SAMPLES / "SCA1B_2003-09-14_A_00.asc",
    "B": SAMPLES / "SCA1B_2003-09-14_B_00.asc",
    "C": SAMPLES / "SCA1B_2023-06-01_C_04.txt",
    "D": SAMPLES / "SCA1B_2023-06-01_D_04.txt",
}
EX, EY, EZ = np.eye(3)


def split_sample(path):
    """(header incl. its end line, data lines) of a sample file."""
    raw = path.read_bytes()
    for marker in (b"# End of YAML header\n", b"END OF HEADER"):
        i = raw.find(marker)
        if i >= 0:
            j = raw.index(b"\n", i) + 1
            return raw[:j], raw[j:].splitlines(keepends=True)
    raise AssertionError(path)


def header_lines(path):
    return split_sample(path)[0].count(b"\n")


def write_variant(tmp_path, letter, edit, name=None):
    """A copy of sample ``letter`` with ``edit(lines)`` applied to its data lines."""
    src = SCA[letter]
    head, data = split_sample(src)
    data = edit(list(data))
    out = tmp_path / (name or src.name)
    out.write_bytes(head + b"".join(data))
    return out


def attitude_of(quats, times=None):
    """An Attitude from scalar-first quaternions (one per epoch)."""
    q = np.atleast_2d(np.asarray(quats, dtype=float))
    n = q.shape[0]
    t = np.arange(n, dtype=float) if times is None else np.asarray(times, dtype=float)
    return Attitude(t, q, np.ones(n, int), np.zeros(n), np.zeros(n, np.uint32))


def qmul(a, b):
    """Hamilton product of scalar-first quaternions (written out, no scipy)."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
            a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
        ]
    )


def conj(q):
    return np.array([q[0], -q[1], -q[2], -q[3]])


def rodrigues(axis, angle, v):
    """Active rotation of v by ``angle`` about unit ``axis`` (right hand)."""
    u = np.asarray(axis, float)
    return v * np.cos(angle) + np.cross(u, v) * np.sin(angle) + u * (u @ v) * (1 - np.cos(angle))


# ---------------------------------------------------------------- real files


@pytest.mark.parametrize(
    ("letter", "satellite", "n", "t0", "t1", "step", "sca_id"),
    [
        ("A", "GRACE-A", 60, 116769600.0, 116769895.0, 5.0, 4),
        ("B", "GRACE-B", 60, 116769600.0, 116769895.0, 5.0, 4),
        ("C", "GRACE-FO-C", 100, 738849600.0, 738849699.0, 1.0, 23),
        ("D", "GRACE-FO-D", 100, 738849600.0, 738849699.0, 1.0, 23),
    ],
)
def test_real_samples(letter, satellite, n, t0, t1, step, sca_id):
    a = read_attitude(SCA[letter])
    assert a.satellite == satellite
    assert len(a) == n == a.quat.shape[0]
    assert (a.time[0], a.time[-1]) == (t0, t1)
    assert np.all(np.diff(a.time) == step)  # strictly increasing, no gap
    assert set(a.sca_id.tolist()) == {sca_id}
    dev = np.abs(np.linalg.norm(a.quat, axis=1) - 1)
    assert dev.max() < 1e-9  # A, B: 2.2e-16; C, D: 9.0e-11
    assert a.meta["attitude"]["max_norm_deviation"] == pytest.approx(dev.max(), abs=1e-16)
    assert a.meta["attitude"]["n_sign_flips"] == 0
    assert np.all(np.einsum("ij,ij->i", a.quat[1:], a.quat[:-1]) > 0.99999)
    if letter in "CD":  # the samples were cut after 100 of 86400 records
        assert a.warnings == ("header announces 86400 data records, file has 100",)
        assert a.meta["gracefo"]["global_attributes"]["platform"] == f"GRACE {letter}"
    else:
        assert a.warnings == ()
        assert a.meta["grace"]["SATELLITE NAME"] == f"GRACE {letter}"


def test_grace_a_values():
    a = read_attitude(SCA["A"])
    # line 29: 116769600 A 4 0.6001211159413961 -0.2133887325030409 0.1857303141739774
    #          0.7482139703579684 4.139514383199252e-05 00000000
    assert a.quat[0].tolist() == [
        0.6001211159413961,
        -0.2133887325030409,
        0.1857303141739774,
        0.7482139703579684,
    ]
    assert a.quatangle[0] == 0.6001211159413961 and a.quatkcoeff[0] == 0.7482139703579684
    assert a.qual_rss[0] == 4.139514383199252e-05
    # line 35: 116769630 A 4 ... 8.407381160414661e-05 10000000  (bit 7, leftmost)
    (i,) = np.flatnonzero(a.time == 116769630)
    assert a.qualflg[i] == 128 and a.qual_rss[i] == 8.407381160414661e-05
    # line 48: 116769695 A 4 ... 10000000; no other record is flagged
    assert a.time[a.qualflg != 0].tolist() == [116769630.0, 116769695.0]


def test_gracefo_c_values():
    a = read_attitude(SCA["C"])
    # first data line: 738849600 C 23 0.07816222822585139 0.1642723922577685
    #                  -0.004109730449778668 0.9833048140804912 8.773305180563576e-07 00000000
    assert a.quat[0].tolist() == [
        0.07816222822585139,
        0.1642723922577685,
        -0.004109730449778668,
        0.9833048140804912,
    ]
    assert a.qual_rss[0] == 8.773305180563576e-07 and a.qualflg[0] == 0


def test_gzip_reads_the_same(tmp_path):
    gz = tmp_path / "SCA1B_2023-06-01_D_04.txt.gz"
    gz.write_bytes(gzip.compress(SCA["D"].read_bytes()))
    a, b = read_attitude(SCA["D"]), read_attitude(gz)
    assert np.array_equal(a.time, b.time) and np.array_equal(a.quat, b.quat)


# ---------------------------------------------------------------- convention


def test_known_rotation_90_about_z():
    # q = cos 45° + k sin 45°: the SRF is the inertial frame turned +90° about z
    c = np.sqrt(0.5)
    att = attitude_of([[c, 0, 0, c], [c, 0, 0, c]])
    t = np.array([0.0, 0.5, 1.0])
    # inertial x is the SRF's -y, inertial y the SRF's +x
    assert np.allclose(rotate_to_srf(t, np.tile(EX, (3, 1)), att), [0, -1, 0], atol=1e-15)
    assert np.allclose(rotate_to_srf(t, np.tile(EY, (3, 1)), att), [1, 0, 0], atol=1e-15)
    assert np.allclose(rotate_to_srf(t, np.tile(EZ, (3, 1)), att), [0, 0, 1], atol=1e-15)
    # the SRF x axis points along inertial +y
    assert np.allclose(rotate_to_inertial(t, np.tile(EX, (3, 1)), att), [0, 1, 0], atol=1e-15)


def test_convention_is_conjugate_sandwich():
    """v_SRF = q* v q and v_I = q v q*, with a Hamilton product written out here."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    v = rng.normal(size=3)
    att = attitude_of([q, q])
    srf = qmul(qmul(conj(q), np.r_[0.0, v]), q)[1:]
    ine = qmul(qmul(q, np.r_[0.0, v]), conj(q))[1:]
    assert np.allclose(rotate_to_srf([0.3], [v], att)[0], srf, rtol=0, atol=1e-15)
    assert np.allclose(rotate_to_inertial([0.3], [v], att)[0], ine, rtol=0, atol=1e-15)
    # and the columns of R(q) = srf_to_inertial are the SRF axes in inertial coordinates
    m = att.srf_to_inertial[0].as_matrix()
    assert np.allclose(m[:, 0], rotate_to_inertial([0.0], [EX], att)[0], atol=1e-15)


def test_round_trip_real_attitude():
    a = read_attitude(SCA["A"])
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(a.time[0], a.time[-1], 500))
    v = rng.normal(size=(500, 3)) * 1e-7  # m/s², a non-gravitational acceleration
    back = rotate_to_inertial(t, rotate_to_srf(t, v, a), a)
    rel = np.linalg.norm(back - v, axis=1) / np.linalg.norm(v, axis=1)
    assert rel.max() <= 1e-15


@pytest.mark.parametrize("flip", [False, True])
def test_slerp_against_analytic_rotation(flip):
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    angle = 0.8  # rad between the two records
    q1 = np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis]
    att = attitude_of([[1, 0, 0, 0], -q1 if flip else q1], times=[100.0, 108.0])
    assert att.meta == {} and continuous_quaternions(att.quat)[1] == 0
    v = np.array([0.3, -1.1, 0.7])
    for frac in (0.0, 0.25, 0.5, 0.9, 1.0):
        t = 100.0 + 8.0 * frac
        # inertial -> SRF is the inverse (active angle -frac·angle about the axis)
        expect = rodrigues(axis, -frac * angle, v)
        got = rotate_to_srf([t], [v], att)[0]
        assert np.allclose(got, expect, rtol=0, atol=1e-14), frac
        got_i = rotate_to_inertial([t], [v], att)[0]
        assert np.allclose(got_i, rodrigues(axis, frac * angle, v), rtol=0, atol=1e-14)


def test_sign_continuity():
    c = np.sqrt(0.5)
    q = np.array([[1, 0, 0, 0], [c, 0, 0, c], [0, 0, 0, 1.0]])
    flipped = q * np.array([1, -1, 1])[:, None]
    fixed, n = continuous_quaternions(flipped)
    assert n == 2 and np.array_equal(fixed, q)
    assert np.array_equal(attitude_of(flipped).quat, q)


# ---------------------------------------------------------------- physics on real data


def _inertial_x(letter):
    a = read_attitude(SCA[letter])
    return a.time, a.srf_to_inertial.apply(EX)


@pytest.mark.parametrize("pair", ["AB", "CD"])
def test_twin_satellites_point_at_each_other(pair):
    """GRACE and GRACE-FO fly with SRF x along the line of sight to the other satellite:
    the two x axes in the inertial frame are antiparallel (no Earth rotation needed)."""
    ta, xa = _inertial_x(pair[0])
    tb, xb = _inertial_x(pair[1])
    assert np.array_equal(ta, tb)
    cos = np.einsum("ij,ij->i", xa, xb)
    assert np.degrees(np.arccos(-cos)).max() < 0.6  # A/B: 0.29-0.46°; C/D: 0.02°
    # the transposed convention would not give this (A/B: 12-18°, C/D: 25-38° off)
    qa = read_attitude(SCA[pair[0]]).srf_to_inertial.inv().apply(EX)
    qb = read_attitude(SCA[pair[1]]).srf_to_inertial.inv().apply(EX)
    assert np.degrees(np.arccos(-np.einsum("ij,ij->i", qa, qb))).min() > 10


def _gnv(path):
    """(time, ECEF position [m], ECEF velocity [m/s]) of a GNV1B sample."""
    rows = [line.split() for line in split_sample(path)[1] if line.strip()]
    t = np.array([float(r[0]) for r in rows])
    pos = np.array([[float(x) for x in r[3:6]] for r in rows])
    vel = np.array([[float(x) for x in r[9:12]] for r in rows])
    return t, pos, vel


def _earth_rotation(t):
    """Earth rotation angle [rad] at GPS times t (UT1 ~ UTC; IERS 2010 eq. 5.15)."""
    utc = gps_to_utc(t)
    tu = (utc - np.datetime64("2000-01-01T12:00:00", "ns")).astype(np.int64) / 86400e9
    return 2 * np.pi * np.mod(0.7790572732640 + 1.00273781191135448 * tu, 1.0)


@pytest.mark.parametrize(
    ("lead", "trail", "day"), [("A", "B", "2003-09-14"), ("C", "D", "2023-06-01")]
)
def test_x_axis_along_line_of_sight_from_orbits(lead, trail, day):
    """The SRF x axis of the leading satellite points at the other one (GNV1B orbits).

    GNV1B is Earth-fixed; it is rotated to the inertial frame about z by the Earth
    rotation angle only (precession-nutation, ~0.05° in 2003 and ~0.3° in 2023, and
    polar motion are neglected), enough to tell the convention from its transpose.
    """
    rel = "00" if lead == "A" else "04"
    ext = "asc" if lead == "A" else "txt"
    tg, pa, va = _gnv(SAMPLES / f"GNV1B_{day}_{lead}_{rel}.{ext}")
    tgb, pb, _ = _gnv(SAMPLES / f"GNV1B_{day}_{trail}_{rel}.{ext}")
    assert np.array_equal(tg, tgb)
    att = read_attitude(SCA[lead])
    t = np.intersect1d(tg, att.time)
    assert t.size >= 5  # A: 5 epochs (GNV1B every 60 s); C: 100
    ig = np.searchsorted(tg, t)
    theta = _earth_rotation(t)
    c, s = np.cos(theta), np.sin(theta)

    def to_inertial(v):
        return np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]])

    omega = np.array([0.0, 0.0, 7.292115e-5])  # rad/s
    ra, rb = to_inertial(pa[ig]), to_inertial(pb[ig])
    vel = to_inertial(va[ig] + np.cross(omega, pa[ig]))
    los = (rb - ra) / np.linalg.norm(rb - ra, axis=1)[:, None]
    x = rotate_to_inertial(t, np.tile(EX, (t.size, 1)), att)
    assert np.degrees(np.arccos(np.einsum("ij,ij->i", x, los))).max() < 0.5  # 0.10-0.24°
    radial = ra / np.linalg.norm(ra, axis=1)[:, None]
    assert np.abs(np.einsum("ij,ij->i", x, radial)).max() < 0.03  # half the 1.5-1.8° separation
    speed = np.linalg.norm(vel, axis=1)
    assert np.all(np.einsum("ij,ij->i", x, vel) / speed < -0.999)  # the leader flies backward
    wrong = att.srf_to_inertial.inv().apply(EX)[np.searchsorted(att.time, t)]
    assert np.degrees(np.arccos(np.einsum("ij,ij->i", wrong, los))).min() > 10


# ---------------------------------------------------------------- coverage and gaps


def test_outside_coverage_and_gaps_give_nan():
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    att = attitude_of(q, times=[0.0, 5.0, 30.0, 35.0])  # a 25-s gap
    t = np.array([-1.0, 0.0, 2.5, 5.0, 10.0, 30.0, 33.0, 35.0, 35.5, np.nan])
    v = np.tile([1.0, 2.0, 3.0], (t.size, 1))
    out = rotate_to_srf(t, v, att)
    nan = np.isnan(out).all(axis=1)
    assert nan.tolist() == [True, False, False, False, True, False, False, False, True, True]
    assert np.array_equal(out[~nan], v[~nan])
    assert np.array_equal(att.covers(t), ~nan)
    assert not np.isnan(rotate_to_srf(t[:-1], v[:-1], att, max_gap=np.inf)[4]).any()
    assert DEFAULT_MAX_GAP == 10.0
    assert np.isnan(rotate_to_inertial([10.0], [[1.0, 0, 0]], att, max_gap=20.0)).all()
    assert not np.isnan(rotate_to_inertial([10.0], [[1.0, 0, 0]], att, max_gap=25.0)).any()


def test_single_record_attitude():
    c = np.sqrt(0.5)
    att = attitude_of([[c, 0, 0, c]], times=[7.0])
    out = rotate_to_srf([7.0, 7.5], [EX, EX], att)
    assert np.allclose(out[0], [0, -1, 0], atol=1e-15) and np.isnan(out[1]).all()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"times": [0.0, 1.0], "vectors": [[1.0, 0, 0]]}, "shape"),
        ({"times": [[0.0]], "vectors": [[1.0, 0, 0]]}, "1-D"),
        ({"max_gap": 0.0}, "positive"),
        ({"max_gap": "10"}, "number of seconds"),
        ({"attitude": "SCA1B.txt"}, "Attitude"),
    ],
)
def test_rotate_validation(kwargs, match):
    args = {"times": [0.5], "vectors": [[1.0, 0, 0]], "attitude": attitude_of([[1, 0, 0, 0]] * 2)}
    max_gap = kwargs.pop("max_gap", DEFAULT_MAX_GAP)
    args.update(kwargs)
    with pytest.raises(ValidationError, match=match):
        rotate_to_srf(args["times"], args["vectors"], args["attitude"], max_gap=max_gap)


def test_attitude_validation():
    with pytest.raises(ValidationError, match="not 1 to"):
        attitude_of([[1.0, 0, 0, 1e-2], [1.0, 0, 0, 0]])
    with pytest.raises(ValidationError, match="strictly increasing"):
        attitude_of([[1.0, 0, 0, 0]] * 2, times=[1.0, 1.0])
    with pytest.raises(ValidationError, match="finite"):
        attitude_of([[np.nan, 0, 0, 0], [1.0, 0, 0, 0]])


# ---------------------------------------------------------------- properties


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


_quat = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)
_vec = st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3).filter(
    lambda v: np.linalg.norm(v) > 1e-6
)


@settings(max_examples=100, deadline=None)
@given(q0=_quat, q1=_quat, v=_vec, frac=st.floats(0, 1), scale=st.sampled_from([1e-9, 1.0, 1e6]))
def test_property_norm_and_inverse(q0, q1, v, frac, scale):
    att = attitude_of([_unit(q0), _unit(q1)], times=[0.0, 5.0])
    vec = np.asarray(v)[None, :] * scale
    t = [5.0 * frac]
    srf = rotate_to_srf(t, vec, att)
    n = np.linalg.norm(vec)
    assert abs(np.linalg.norm(srf) - n) <= 1e-15 * 4 * n
    back = rotate_to_inertial(t, srf, att)
    # <= 1e-15 on the real data; over 10^4 random cases the worst is 1.07e-15 (~5 ulp)
    assert np.linalg.norm(back - vec) <= 2e-15 * n


# ---------------------------------------------------------------- damaged files


def _line_of(path, k):
    """1-based file line of data line k (0-based) of a sample copy."""
    return header_lines(path) + 1 + k


def test_one_non_unit_quaternion_is_left_out_with_a_warning_naming_its_line(tmp_path):
    """QA (2026-11-30): one changed digit in one record failed the whole day."""

    def edit(lines):
        f = lines[7].split(b" ")
        f[3] = b"0.7001211159413961"  # one changed digit of quatangle
        lines[7] = b" ".join(f)
        return lines

    whole = read_attitude(SCA["A"])
    p = write_variant(tmp_path, "A", edit)
    a = read_attitude(p)
    line = _line_of(SCA["A"], 7)
    assert line == 36
    (w,) = [w for w in a.warnings if "damaged" in w]
    assert "1 record(s)" in w and f"line {line}" in w and "\n" not in w
    assert len(a) == len(whole) - 1
    assert whole.time[7] not in a.time
    assert a.meta["attitude"]["max_norm_deviation"] < NORM_TOLERANCE
    # the rotation at the lost epoch is interpolated across the hole (SLERP over 10 s;
    # the real attitude's control wobble leaves 2e-4 rad): within 1e-3 of the record's
    v = np.array([[-2e-7, 3e-8, 1e-8]])
    at = whole.time[7:8]
    exact = rotate_to_srf(at, v, whole)
    assert np.linalg.norm(rotate_to_srf(at, v, a) - exact) < 1e-3 * np.linalg.norm(v)


def test_many_non_unit_quaternions_are_an_error_naming_the_first_line(tmp_path):
    def edit(lines):
        for k in range(3, 20, 2):
            f = lines[k].split(b" ")
            f[3] = b"0.7" + f[3][3:][::-1]  # scrambled digits
            lines[k] = b" ".join(f)
        return lines

    p = write_variant(tmp_path, "A", edit)
    with pytest.raises(FormatError) as exc:
        read_attitude(p)
    line = _line_of(SCA["A"], 3)
    assert exc.value.line == line
    assert str(exc.value).startswith(f"{p}:{line}: quaternion norm ")
    assert "not a rotation" in str(exc.value) and "\n" not in str(exc.value)


def test_small_norm_deviation_accepted(tmp_path):
    def edit(lines):
        f = lines[3].split(b" ")
        f[6] = repr(float(f[6]) * (1 + 2e-7)).encode()  # quatkcoeff ~0.98: |q| - 1 ~ 2e-7
        lines[3] = b" ".join(f)
        return lines

    a = read_attitude(write_variant(tmp_path, "C", edit))
    assert 1e-8 < a.meta["attitude"]["max_norm_deviation"] < NORM_TOLERANCE


@pytest.mark.parametrize(
    ("k", "edit", "match"),
    [
        (4, lambda f: f[:-1], "wrong number of columns: expected 9"),
        (5, lambda f: [*f[:4], b"0.18x", *f[5:]], "quaticoeff: not a finite number"),
        (6, lambda f: [*f[:3], b"NaN", *f[4:]], "quatangle: not a finite number"),
        (7, lambda f: [*f[:2], b"4.5", *f[3:]], "sca_id: not an integer"),
        (8, lambda f: [f[0], b"E", *f[2:]], "satellite id 'E'"),
        (9, lambda f: [*f[:8], b"0000002\n"], "qualflg"),
        (10, lambda f: [b"9e99", *f[1:]], "gps_time"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, k, edit, match):
    def change(lines):
        lines[k] = b" ".join(edit(lines[k].split(b" ")))
        if not lines[k].endswith(b"\n"):
            lines[k] += b"\n"
        return lines

    p = write_variant(tmp_path, "B", change)
    with pytest.raises(FormatError, match=match) as exc:
        read_attitude(p)
    assert exc.value.line == _line_of(SCA["B"], k)
    assert str(exc.value).startswith(f"{p}:{exc.value.line}: ")
    assert isinstance(exc.value, AccalError)


def test_truncated_last_line(tmp_path):
    p = write_variant(tmp_path, "D", lambda lines: [*lines[:-1], lines[-1][:40]])
    with pytest.raises(FormatError, match="truncated last line") as exc:
        read_attitude(p)
    assert exc.value.line == _line_of(SCA["D"], 99)


def test_sign_flipped_record_is_made_continuous(tmp_path):
    def edit(lines):
        f = lines[20].split(b" ")
        for j in range(3, 7):
            f[j] = f[j][1:] if f[j].startswith(b"-") else b"-" + f[j]
        lines[20] = b" ".join(f)
        return lines

    a = read_attitude(write_variant(tmp_path, "C", edit))
    assert a.meta["attitude"]["n_sign_flips"] == 2
    assert np.array_equal(a.quat, read_attitude(SCA["C"]).quat)


def test_out_of_order_and_duplicates(tmp_path):
    a = read_attitude(
        write_variant(tmp_path, "A", lambda lines: [lines[1], lines[0], lines[1], *lines[2:]])
    )
    assert len(a) == 60 and np.all(np.diff(a.time) > 0)
    assert any("out of time order" in w for w in a.warnings)
    assert any("duplicated epochs" in w for w in a.warnings)


def test_other_products_refused(tmp_path):
    with pytest.raises(UnsupportedFormatError, match="not SCA1B"):
        read_attitude(SAMPLES / "ACC1B_2003-09-14_A_00.asc")
    with pytest.raises(UnsupportedFormatError, match="not the SCA1B columns"):
        read_attitude(SAMPLES / "ACT1B_2023-06-01_C_04.txt")
    raw = SCA["A"].read_bytes().replace(b"0=BINARY 1=ASCII  : 1", b"0=BINARY 1=ASCII  : 0")
    p = tmp_path / "SCA1B_2003-09-14_A_00.dat"
    p.write_bytes(raw)
    with pytest.raises(UnsupportedFormatError, match="binary SCA1B"):
        read_attitude(p)
    with pytest.raises(FormatError, match="no such file"):
        read_attitude(tmp_path / "missing.asc")


# ---------------------------------------------------------------- find_attitude_file


def test_find_attitude_file_samples():
    assert find_attitude_file(SAMPLES / "ACC1B_2003-09-14_A_00.asc") == SCA["A"]
    assert find_attitude_file(SAMPLES / "ACC1B_2003-09-14_B_00.dat") == SCA["B"]
    assert find_attitude_file(str(SAMPLES / "ACT1B_2023-06-01_C_04.txt")) == SCA["C"]
    assert find_attitude_file(SAMPLES / "ACT1B_2023-06-01_D_04.txt") == SCA["D"]
    assert find_attitude_file(SAMPLES / "AHK1B_2003-09-14_A_00.asc") is None
    assert find_attitude_file(SAMPLES / "ACC1B_2003-09-14_A_02.asc") is None  # other release


def test_find_attitude_file_gz(tmp_path):
    (tmp_path / "SCA1B_2010-01-01_A_02.asc.gz").write_bytes(b"")
    acc = tmp_path / "ACC1B_2010-01-01_A_02.asc.gz"
    assert find_attitude_file(acc) == tmp_path / "SCA1B_2010-01-01_A_02.asc.gz"
    assert find_attitude_file(tmp_path / "ACC1B_2010-01-01_A_02.asc") == (
        tmp_path / "SCA1B_2010-01-01_A_02.asc.gz"
    )
    (tmp_path / "SCA1B_2010-01-01_A_02.asc").write_bytes(b"")
    assert find_attitude_file(tmp_path / "ACC1B_2010-01-01_A_02.asc") == (
        tmp_path / "SCA1B_2010-01-01_A_02.asc"
    )
    (tmp_path / "SCA1B_2020-01-01_C_04.txt.gz").write_bytes(b"")
    assert find_attitude_file(tmp_path / "ACT1B_2020-01-01_C_04.txt.gz") == (
        tmp_path / "SCA1B_2020-01-01_C_04.txt.gz"
    )
    assert find_attitude_file(tmp_path / "ACT1B_2020-01-01_D_04.txt.gz") is None
    assert find_attitude_file(tmp_path / "notes.txt") is None
