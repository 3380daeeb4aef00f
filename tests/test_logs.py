"""Drive logs as an engineer records them (jaxobs.signals.read_drive_log): the declared layout, the streaming
reader, and one test per silent mistake a log can carry, each now a one-line error or warning naming the column."""

import math
import re
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxobs
from jaxobs import drive as D
from jaxobs import papers
from jaxobs.signals import RecordingLayout, RecordingWarning, read_drive_log

ROOT = Path(__file__).resolve().parents[1]
DRIVE_CSV = ROOT / "tuning" / "presets" / "recordings" / "drive_spmsm_1000rpm.csv"
NAMES = ["t", "u_a", "u_b", "i_a", "i_b", "theta_e", "omega_e"]
S3 = math.sqrt(3.0)


def _cols():
    """The shipped log's columns (000's SPMSM at 1000 r/min, α-β, applied voltages, electrical rad and rad/s)."""
    return dict(zip(NAMES, np.loadtxt(DRIVE_CSV, delimiter=",", comments="#", skiprows=2).T))


def _write(path, cols: dict, fmt="%.17g", delimiter=","):
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=delimiter, header=delimiter.join(cols),
               comments="", fmt=fmt)  # fmt: skip
    return path


def _read(path, **kw):
    kw.setdefault("time_column", "t")
    kw.setdefault("omega_e", "omega_e")
    return read_drive_log(path, **kw)


def test_default_layout_reads_what_drive_recording_reads():
    """A file in the observers' own form needs no declaration: the same samples, truth and speed, bit for bit,
    as jaxobs.DriveRecording.from_csv."""
    old = jaxobs.DriveRecording.from_csv(DRIVE_CSV, time_column="t", theta_e="theta_e", omega_e="omega_e")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a clean log warns of nothing
        log = _read(DRIVE_CSV, machine=D.spmsm_paper000(inertia="motor"))
    assert log.n == 3000 and log.warnings == []
    new = log.recording()
    for a, b in zip(jax.tree.leaves(old), jax.tree.leaves(new)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert new.ts == old.ts


def _sosoifo_theta(rec):
    par = D.spmsm_paper000(inertia="motor")
    k1, k2 = papers.SECOND_ORDER_SOIFO_K1, papers.SECOND_ORDER_SOIFO_K2
    obs = jaxobs.SecondOrderSOIFO(par.Rs, par.Ld, k1, k2, k1**3 / (2 * k2), 2 * math.pi * 50)
    sol = jaxobs.simulate(jaxobs.OnSignal(obs, rec), 0.2)
    return np.asarray(sol.outputs.obs.theta)


def test_phase_currents_and_reference_voltages_give_the_alpha_beta_applied_estimate(tmp_path):
    """The same drive logged as a controller logs it: phase currents a, b and the voltage reference computed at
    t_k (applied over [t_k+1, t_k+2]), in the d-q frame of the angle the controller used.  Declared, it gives the
    estimate of the α-β applied-voltage form, from the row the reference's delay leaves first, to 1e-9."""
    c = _cols()
    th = c["theta_e"]
    # the log: row k holds i at t_k and the reference u*[k] = the voltage applied over [t_k+1, t_k+2]
    u_ref_a, u_ref_b = np.roll(c["u_a"], -1), np.roll(c["u_b"], -1)  # the last row's reference is never applied
    cos, sin = np.cos(th), np.sin(th)
    u_d, u_q = cos * u_ref_a + sin * u_ref_b, -sin * u_ref_a + cos * u_ref_b  # the reference in the d-q frame
    logged = {
        "t": c["t"],
        "ua_d": u_d,
        "ua_q": u_q,
        "ia": c["i_a"],
        "ib": -0.5 * c["i_a"] + S3 / 2 * c["i_b"],
        "theta_e": th,
        "omega_e": c["omega_e"],
    }
    layout = RecordingLayout(current_frame="abc", voltage_frame="dq", voltage_timing="reference", voltage_delay=1)
    log = _read(_write(tmp_path / "ctrl.csv", logged), voltages=["ua_d", "ua_q"], currents=["ia", "ib"], layout=layout)
    assert log.n == 2999 and log.t0 == pytest.approx(1e-4)
    # today's form of the same data, from row 1 on
    ref = _write(tmp_path / "ab.csv", {k: v[1:] for k, v in c.items()})
    old = jaxobs.DriveRecording.from_csv(ref, time_column="t", theta_e="theta_e", omega_e="omega_e")
    new = log.recording()
    np.testing.assert_allclose(np.asarray(new.samples), np.asarray(old.samples), rtol=0, atol=1e-9)
    np.testing.assert_allclose(_sosoifo_theta(new), _sosoifo_theta(old), rtol=0, atol=1e-9)
    # undeclared, the same file is refused, naming the columns and the declaration
    with pytest.raises(ValueError, match=r"columns 'ia, ib' are not an α-β pair .*current_frame = 'abc'"):
        _read(tmp_path / "ctrl.csv", voltages=["ua_d", "ua_q"], currents=["ia", "ib"],
              layout=RecordingLayout(voltage_frame="dq", voltage_timing="reference"))  # fmt: skip


def test_sidecar_declares_the_layout(tmp_path):
    c = _cols()
    c["i_b"] = -0.5 * c["i_a"] + S3 / 2 * c["i_b"]
    path = _write(tmp_path / "log.csv", c)
    Path(str(path) + ".toml").write_text('[layout]\ncurrent_frame = "abc"\n')
    assert _read(path).n == 3000
    Path(str(path) + ".toml").write_text('[layout]\ncurrent_frames = "abc"\n')
    with pytest.raises(ValueError, match=r"log.csv.toml: layout.current_frames: unknown key"):
        _read(path)


# one test per silent mistake: each is refused in one line naming the column and the declaration meant
P = 3  # 000's SPMSM's pole pairs


def _mistake(c, which):
    th, om = c["theta_e"], c["omega_e"]
    if which == "phase currents in the α-β columns":
        c["i_b"] = -0.5 * c["i_a"] + S3 / 2 * c["i_b"]
    elif which == "angle in degrees":
        c["theta_e"] = np.degrees(np.mod(th, 2 * math.pi))
    elif which == "mechanical angle":
        c["theta_e"] = np.mod(np.unwrap(th) / P, 2 * math.pi)
    elif which == "speed in r/min":
        c["omega_e"] = om / P * 60 / (2 * math.pi)
    elif which == "mechanical speed":
        c["omega_e"] = om / P
    elif which == "flipped β sign":
        c["u_b"], c["i_b"] = -c["u_b"], -c["i_b"]
    elif which == "time in ms":
        c["t"] = c["t"] * 1000
    elif which == "power against the machine":
        c["u_a"], c["u_b"] = -c["u_a"], -c["u_b"]
    return c


MISTAKES = [
    ("phase currents in the α-β columns", r"columns 'i_a, i_b' are not an α-β pair .* current_frame = 'abc'"),
    ("angle in degrees", r"column 'theta_e' wraps by about 360: it is in degrees \(declare angle_unit = 'deg'\)"),
    ("mechanical angle", r"column 'omega_e' is 3.* the slope of column 'theta_e'.*angle_kind = 'mechanical'"),
    ("speed in r/min", r"column 'omega_e' is 3.* the slope.*speed_unit = 'r/min', speed_kind = 'mechanical'; p = 3"),
    ("mechanical speed", r"column 'omega_e' is 0.33.* the slope.*speed_kind = 'mechanical'; ratio 1/3"),
    ("flipped β sign", r"columns 'u_a, u_b' turn against the angle column 'theta_e'.*flipped β sign"),
    ("time in ms", r"time column 't' steps by 0.1 s \(10 Hz\), too slow.*ms or us\? \(declare time_unit\)"),
    ("power against the machine", r"power into the machine from columns 'u_a, u_b' and 'i_a, i_b' is -4"),
]


@pytest.mark.parametrize("which,match", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_each_silent_mistake_is_refused_naming_the_column(tmp_path, which, match):
    path = _write(tmp_path / "log.csv", _mistake(_cols(), which))
    with pytest.raises(ValueError, match=match) as e:
        _read(path, machine=D.spmsm_paper000(inertia="motor"))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    "which,layout",
    [
        ("angle in degrees", RecordingLayout(angle_unit="deg")),
        ("mechanical angle", RecordingLayout(angle_kind="mechanical", pole_pairs=P)),
        ("speed in r/min", RecordingLayout(speed_unit="r/min", speed_kind="mechanical", pole_pairs=P)),
        ("mechanical speed", RecordingLayout(speed_kind="mechanical", pole_pairs=P)),
        ("time in ms", RecordingLayout(time_unit="ms")),
    ],
)
def test_declared_units_read_the_same_log(tmp_path, which, layout):
    """Declared, each unit reads back the observers' form (to the conversion's rounding)."""
    base = _read(DRIVE_CSV)
    log = _read(_write(tmp_path / "log.csv", _mistake(_cols(), which)), layout=layout)
    d = np.asarray(log.theta_e) - np.asarray(base.theta_e)
    np.testing.assert_allclose(np.remainder(d + math.pi, 2 * math.pi) - math.pi, 0, atol=1e-9)
    np.testing.assert_allclose(log.omega_e, base.omega_e, rtol=1e-12)
    assert log.ts == pytest.approx(base.ts, rel=1e-12)


def test_phase_offset_and_gain_mismatch_warn(tmp_path):
    c = _cols()
    a, b = c["i_a"], -0.5 * c["i_a"] + S3 / 2 * c["i_b"]
    amp = float(np.max(np.abs(a)))
    c["i_a"], c["i_b"] = a + 0.05 * amp, 1.06 * b  # a 5 % offset on a, a 6 % gain error on b
    with pytest.warns(RecordingWarning) as rec:
        _read(_write(tmp_path / "log.csv", c), layout=RecordingLayout(current_frame="abc"))
    text = " | ".join(str(w.message) for w in rec)
    assert "columns 'i_a, i_b' carry a DC offset of" in text
    assert "columns 'i_a, i_b' are unbalanced" in text


def test_reference_voltages_declared_as_applied_warn(tmp_path):
    """The controller's references at t_k written as applied voltages: every estimate biased by ω_e·ts (+1.06°
    at 600 r/min on 000's SPMSM at 10 kHz): a warning naming the columns and the declaration."""
    c = _cols()
    c["u_a"], c["u_b"] = np.roll(c["u_a"], -1), np.roll(c["u_b"], -1)
    with pytest.warns(RecordingWarning, match=r"columns 'u_a, u_b' match the machine's model best 1 period"):
        _read(_write(tmp_path / "log.csv", c), machine=D.spmsm_paper000(inertia="motor"))


def test_three_phases_that_do_not_sum_to_zero(tmp_path):
    c = _cols()
    a = c["i_a"]
    b = -0.5 * a + S3 / 2 * c["i_b"]
    cols = {"t": c["t"], "u_a": c["u_a"], "u_b": c["u_b"], "ia": a, "ib": b, "ic": -a - b,
            "theta_e": c["theta_e"], "omega_e": c["omega_e"]}  # fmt: skip
    lay = RecordingLayout(current_frame="abc")
    log = _read(_write(tmp_path / "ok.csv", cols), currents=["ia", "ib", "ic"], layout=lay)
    np.testing.assert_allclose(log.i_b, c["i_b"], atol=1e-12)
    cols["ic"] = 0.5 * cols["ic"]
    with pytest.raises(ValueError, match=r"three current columns 'ia, ib, ic' do not sum to zero"):
        _read(_write(tmp_path / "bad.csv", cols), currents=["ia", "ib", "ic"], layout=lay)


def test_delimiter_and_decimal_mark_hints(tmp_path):
    c = {k: v[:200] for k, v in _cols().items()}
    path = tmp_path / "semi.csv"
    with open(path, "w") as f:
        f.write(";".join(c) + "\n")
        for row in np.column_stack(list(c.values())):
            f.write(";".join(repr(float(x)).replace(".", ",") for x in row) + "\n")
    with pytest.raises(ValueError, match=r"line 2 .*\(declare delimiter = ';', decimal = ','\)"):
        _read(path)
    log = _read(path, layout=RecordingLayout(delimiter=";", decimal=","))
    np.testing.assert_array_equal(np.asarray(log.i_a), c["i_a"])  # every digit, as Python reads a float


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(current_frame="dq"), r"RecordingLayout.current_frame must be one of 'alpha_beta', 'abc', got 'dq'"),
        (dict(voltage_delay=0), r"voltage_delay must be an integer number of periods in 1..4"),
        (dict(speed_kind="mechanical"), r"speed_kind = 'mechanical' needs pole_pairs"),
        (dict(decimal=","), r"decimal ',' needs another delimiter"),
        (dict(angle_unit="grad"), r"angle_unit must be one of 'rad', 'deg'"),
    ],
)
def test_layout_refuses_bad_values(kw, match):
    with pytest.raises(ValueError, match=match):
        RecordingLayout(**kw)


def _rss_of_reading(tmp_path, rows):
    """Peak RSS (MiB) of a fresh process that reads a synthetic log of ``rows`` rows (and the file's size)."""
    path = tmp_path / f"log{rows}.csv"
    script = textwrap.dedent(f"""
        import math, resource, numpy as np
        rows, ts, w = {rows}, 1e-4, 2 * math.pi * 50
        with open({str(path)!r}, "w") as f:
            f.write("u_a,u_b,i_a,i_b,theta_e\\n")
            for a in range(0, rows, 200_000):
                t = ts * np.arange(a, min(a + 200_000, rows))
                th = w * t
                blk = np.column_stack([100 * np.cos(th + 1.6), 100 * np.sin(th + 1.6), 3 * np.cos(th + 1.7),
                                       3 * np.sin(th + 1.7), np.mod(th, 2 * math.pi)])
                np.savetxt(f, blk, delimiter=",", fmt="%.9g")
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        from jaxobs.signals import read_drive_log
        log = read_drive_log({str(path)!r}, sample_rate=1e4)
        assert log.n == rows, log.n
        rec = log.recording(rows // 2, 5000)
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, rec.n)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    size = path.stat().st_size / 2**20
    path.unlink()
    return float(out.stdout.split()[0]), size


@pytest.mark.slow
def test_a_long_log_reads_at_flat_memory(tmp_path):
    """10^5 and 10^7 rows (about 17 minutes at 10 kHz): the peak RSS of the read differs by less than 120 MiB,
    where holding the 10^7 rows' five float64 columns in memory alone would take 380 MiB (measured: 337 MiB at 10^7
    rows against 314 at 10^5; the difference is pandas' chunk of 500 000 rows.  The field count's running count of
    every byte, int64 over 16 MiB blocks, had taken it to about 700 MiB: benchmarks/log_memory.py)."""
    small, _ = _rss_of_reading(tmp_path, 100_000)
    big, size = _rss_of_reading(tmp_path, 10_000_000)
    print(f"peak RSS {small:.0f} MiB (1e5 rows), {big:.0f} MiB (1e7 rows, {size:.0f} MiB of CSV)")
    assert big - small < 120


def test_a_byte_order_mark_is_no_part_of_the_first_column(tmp_path):
    """A spreadsheet's UTF-8 export begins with a byte-order mark: the log reads as the same file without one."""
    plain = _write(tmp_path / "plain.csv", _cols())
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    a, b = _read(plain).recording(), _read(bom).recording()
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_a_missing_folder_for_the_columns_is_one_line(tmp_path):
    with pytest.raises(ValueError, match="is not an existing folder"):
        _read(DRIVE_CSV, folder=tmp_path / "missing")


def test_provenance_hashes_a_file_in_blocks_to_the_digest_of_its_bytes(tmp_path):
    import hashlib

    from jaxobs.io.provenance import sha256

    data = np.random.default_rng(0).bytes(3 * (1 << 20) + 17)  # over three blocks, the last one partial
    f = tmp_path / "x.bin"
    f.write_bytes(data)
    assert sha256(f) == sha256(data) == hashlib.sha256(data).hexdigest()


def test_rounded_time_stamps_run_on_the_observers_grid():
    """A recording whose interval is the observer's to the reader's tolerance (time stamps printed to 12 digits:
    ts = 9.99999999997669e-05 for 1e-4) runs as the exact one does: the same samples, the same estimates."""
    from jaxobs.observers import SOIFO

    c = _cols()
    ts = float(c["t"][1] - c["t"][0])
    args = (c["u_a"], c["u_b"], c["i_a"], c["i_b"])
    exact = jaxobs.DriveRecording(*args, ts, theta_e=c["theta_e"])
    rounded = jaxobs.DriveRecording(*args, ts * (1 - 2.331e-12), theta_e=c["theta_e"])
    obs = SOIFO.closed_form(Rs=papers.SPMSM_000["Rs"], L=papers.SPMSM_000["Ld"], ts=ts)
    t1 = 200 * ts
    a = jaxobs.simulate(jaxobs.OnSignal(obs, exact), t1).outputs
    b = jaxobs.simulate(jaxobs.OnSignal(obs, rounded), t1).outputs
    for x, y in zip(jax.tree.leaves(a.obs), jax.tree.leaves(b.obs)):  # the estimates: the same samples, bit for bit
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    for x, y in zip(
        jax.tree.leaves(a.truth), jax.tree.leaves(b.truth)
    ):  # the truth: ω = dθ/dt over each ts (2.3e-12 apart)
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-11)
    with pytest.raises(ValueError, match="must equal the observer"):  # beyond the tolerance: refused
        jaxobs.OnSignal(obs, jaxobs.DriveRecording(*args, ts * (1 + 1e-6), theta_e=c["theta_e"]))


@pytest.mark.parametrize(
    "text, match",
    [
        ("[layout]\nx = " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper"),
        ("[layout]\ncurrent_frame = 'abc'\nz = 1" + "0" * 5000 + "\n", "digits"),
        ("[layout]\ncurrent_frame = \xff\n", "not UTF-8"),
    ],
    ids=["deep nesting", "long number", "not utf-8"],
)
def test_a_hostile_sidecar_is_one_line(tmp_path, text, match):
    csv = _write(tmp_path / "log.csv", _cols())
    (tmp_path / "log.csv.toml").write_bytes(text.encode("latin-1"))
    with pytest.raises(ValueError, match=match) as e:
        RecordingLayout.sidecar(csv)
    assert "\n" not in str(e.value) and "log.csv.toml" in str(e.value)


def test_a_declared_voltage_delay_one_period_too_long_warns(tmp_path):
    """References applied one period after they are logged, declared with a delay of 2: the voltages as read lag
    the machine's model by a period (a bias of −ω_e·ts in every estimate): a warning naming the columns and the
    delay to declare.  Declared right, the same file warns of nothing."""
    c = _cols()
    c["u_a"], c["u_b"] = np.roll(c["u_a"], -1), np.roll(c["u_b"], -1)  # row k: the reference applied from t_k+1
    f = _write(tmp_path / "log.csv", c)
    too_long = RecordingLayout(voltage_timing="reference", voltage_delay=2)
    with pytest.warns(RecordingWarning, match=r"'u_a, u_b' match .* 1 period\(s\) earlier .*voltage_delay = 1;"):
        _read(f, machine=D.spmsm_paper000(inertia="motor"), layout=too_long)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _read(
            f,
            machine=D.spmsm_paper000(inertia="motor"),
            layout=RecordingLayout(voltage_timing="reference", voltage_delay=1),
        )


def test_a_file_cut_inside_its_last_line_is_refused_naming_the_line(tmp_path):
    """A copy cut short inside a used field (the last ω read as 187 instead of 187.84) is an error naming the
    line: a file must end its last line."""
    text = _write(tmp_path / "whole.csv", _cols()).read_text()
    n = text.count("\n")
    for cut in (text.rstrip("\n")[:-8], text.rstrip("\n")):  # cut inside a field; whole but without a line end
        f = tmp_path / "cut.csv"
        f.write_text(cut)
        with pytest.raises(ValueError, match=rf"line {n}, the last, has no line end: the file may be cut short"):
            _read(f)


def _abc(c):
    """The log's currents as phases a and b (amplitude-invariant Clarke inverted)."""
    c["i_a"], c["i_b"] = c["i_a"], -0.5 * c["i_a"] + S3 / 2 * c["i_b"]
    return c


def test_a_clean_phase_log_with_steps_warns_nothing(tmp_path):
    """The shipped log holds a speed step at 0.1 s and a load step at 0.2 s; here its currents also double at
    0.15 s, balanced (a clean step).  Read as phase currents, the balance check keeps to the windows whose
    amplitude holds, and the log warns of no offset or unbalance (a window across the step read a DC offset of
    2.2 %)."""
    c = _abc(_cols())
    step = np.where(c["t"] >= 0.15, 2.0, 1.0)
    c["i_a"], c["i_b"] = c["i_a"] * step, c["i_b"] * step
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        log = _read(_write(tmp_path / "abc.csv", c), layout=RecordingLayout(current_frame="abc"))
    assert log.warnings == []


@pytest.mark.parametrize(
    "frame, offset, gain, warned",
    [
        ("abc", 0.0, 0.035, r"gain mismatch of about 3\.[3-7] % between their phases"),
        ("abc", 0.03, 0.0, r"DC offset of about (2\.[89]|3|3\.[0-2]) % of the amplitude on one of their phases"),
        (
            "alpha_beta",
            0.05,
            0.0,
            r"DC offset of about (4\.[89]|5|5\.[0-2]) % of the amplitude on one of their channels",
        ),
        ("alpha_beta", 0.0, 0.04, r"gain mismatch of about (3\.[89]|4|4\.[0-2]) % between their channels"),
        ("abc", 0.01, 0.01, None),  # below both thresholds
    ],
)
def test_offsets_and_gain_errors_warn_with_their_size_in_either_frame(tmp_path, frame, offset, gain, warned):
    c = {k: v[:1000] for k, v in _cols().items()}  # the steady 0.1 s before the speed step
    c = _abc(c) if frame == "abc" else c
    amp = float(np.max(np.abs(c["i_a"])))
    c["i_a"] = (1 + gain) * c["i_a"] + offset * amp
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always", RecordingWarning)
        _read(_write(tmp_path / "log.csv", c), layout=RecordingLayout(current_frame=frame))
    text = " | ".join(str(w.message) for w in rec if isinstance(w.message, RecordingWarning))
    if warned is None:
        assert text == ""
    else:
        assert re.search(warned, text), text  # the size read back within 0.2 % (the clean log's own 0.16 %)


def test_a_mechanical_angle_under_declared_phases_names_the_angle(tmp_path):
    """Phase currents declared as such, with the angle column mechanical but read as electrical: the columns do
    not turn with the angle, and the message names the angle's declaration, not the frame already declared."""
    c = _abc(_cols())
    c["theta_e"] = np.mod(np.unwrap(c["theta_e"]) / P, 2 * math.pi)
    del c["omega_e"]
    layout = RecordingLayout(current_frame="abc")
    with pytest.raises(ValueError, match=r"the angle column 'theta_e' does not turn with them: .*angle_kind") as e:
        _read(_write(tmp_path / "log.csv", c), omega_e=None, layout=layout)
    assert "declare current_frame" not in str(e.value)


@pytest.mark.parametrize("delimiter", [",", ";"])
def test_a_row_with_extra_or_missing_fields_is_named_not_dropped(tmp_path, delimiter):
    """The columns' parser reads only the columns asked for, and used to drop a row's extra fields unseen (and fill
    a missing one with NaN): the log and the recording reader, one reader, name the line."""
    from jaxobs.signals._layout import RecordingLayout

    path = _write(tmp_path / "log.csv", _cols(), delimiter=delimiter)
    lines = path.read_text().splitlines(keepends=True)
    layout = RecordingLayout(delimiter=delimiter)
    for k, (edit, fields) in enumerate(
        ((lambda s: s.rstrip("\n") + delimiter + "7\n", 8), (lambda s: s.split(delimiter, 1)[1], 6))
    ):
        bad = lines[:5] + [edit(lines[5])] + lines[6:]
        p = tmp_path / f"bad{k}.csv"
        p.write_text("".join(bad))
        with pytest.raises(ValueError, match=rf"line 6 has {fields} fields, the file 7$"):
            _read(p, layout=layout)


@pytest.mark.parametrize(
    "which,layout",
    [
        ("angle in degrees", RecordingLayout(angle_unit="deg")),
        ("phase currents in the α-β columns", RecordingLayout(current_frame="abc")),
    ],
)
def test_a_log_at_another_rate_is_read_with_its_sidecar_and_resampled(tmp_path, which, layout):
    """A log recorded faster than the observer runs (10 kHz, read at 5 kHz) is read with its declared layout (here
    a sidecar), converted, then resampled (LogData.resampled): the clean file's samples, as DriveRecording.from_csv
    resamples them; it was re-read without its layout, degrees taken as radians and abc as α-β."""
    from jaxobs.signals import read_recorded

    path = _write(tmp_path / "log.csv", _mistake(_cols(), which))
    key = "angle_unit" if "deg" in which else "current_frame"
    side = {"angle_unit": "deg", "current_frame": "abc"}[key]
    Path(str(path) + ".toml").write_text(f'[layout]\n{key} = "{side}"\n')
    cols, truth = ["u_a", "u_b", "i_a", "i_b"], ["theta_e", "omega_e"]
    got = read_recorded(path, cols, truth, drive=True, time_column="t", ts=2e-4)
    assert layout == RecordingLayout(**{key: side})
    kw = dict(time_column="t", theta_e="theta_e", omega_e="omega_e", ts=2e-4)
    want = jaxobs.DriveRecording.from_csv(DRIVE_CSV, columns=cols, **kw)
    assert got.ts == want.ts == 2e-4 and got.samples.shape == want.samples.shape == (4, 1500)
    for k, name in enumerate(cols):  # u_α, u_β averaged over each 0.2 ms; i_α, i_β interpolated
        a, b = np.asarray(got.samples[k]), np.asarray(want.samples[k])
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(b))), err_msg=name)
    np.testing.assert_allclose(got.omega_e, want.omega_e, rtol=1e-9)
    d = np.asarray(got.theta_e) - np.asarray(want.theta_e)  # the degrees' wrap: whole turns apart at most
    np.testing.assert_allclose(np.remainder(d + math.pi, 2 * math.pi) - math.pi, 0, atol=1e-9)
    with pytest.raises(ValueError, match="windows are cut at the log's own rate"):
        read_recorded(path, cols, truth, drive=True, time_column="t", ts=2e-4, windows=(2, 100))


@pytest.mark.parametrize("block", [23, 64, 1 << 22])
def test_field_counts_are_checked_across_blocks(tmp_path, block):
    """The field count of every line, counted a block of bytes at a time (the delimiters' positions per line): a
    line cut by a block's edge counts whole, a comment or blank line not at all, and the first bad line is named
    whatever the block."""
    from jaxobs.signals._logfile import check_field_counts

    lines = ["t,a,b", "# a comment, with, commas", *(f"{k},{k * 0.5},{-k}" for k in range(40)), ""]
    good = tmp_path / "good.csv"
    good.write_text("\n".join(lines) + "\n")
    check_field_counts(good, RecordingLayout(), 3, block=block)
    bad = list(lines)
    bad[30] = bad[30] + ",7"  # line 31 of the file
    (tmp_path / "bad.csv").write_text("\n".join(bad) + "\n")
    with pytest.raises(ValueError, match=r"line 31 has 4 fields, the file 3$"):
        check_field_counts(tmp_path / "bad.csv", RecordingLayout(), 3, block=block)
