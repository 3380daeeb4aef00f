"""Every command takes a drive file: a job's ``[drive] file`` (or its tables inline), the registry's refusals of
machines a component does not support, and a job on a machine unlike both benches (the Teknic M-2310P of
docs/examples) through ``jaxobs tune``, ``jaxobs envelope --check`` and ``jaxobs export --check``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from jaxobs.drive import bench_machine, dual_ipmsm_paper002, read_drive
from jaxobs.studies.registry import REGISTRY, registered
from jaxobs_tuning.cli import main
from jaxobs_tuning.job import JobError, job_drive, load_job, parse_job
from jaxobs_tuning.study_file import load_study

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"
TEKNIC = EXAMPLES / "teknic_m2310p.toml"

JOB = """
[job]
name = "teknic"
component = "{comp}"
[gains.{gain}]
init = {init}
[drive]
{drive}
[scenarios]
signal = "drive"
t_event = 0.02
horizon = 0.06
steady_from = 0.03
[scenarios.grid]
speed_rpm = [{speeds}]
[objective]
terms = [{{ metric = "rms_position_steady", weight = 1.0 }}]
[solver]
kind = "adam"
steps = 2
"""


def _job(
    tmp_path: Path,
    drive: str = 'file = "teknic.toml"',
    comp="CLESO",
    gain="omega0",
    init=1570.8,
    speeds="1000.0, 3000.0",
):
    shutil.copy(TEKNIC, tmp_path / "teknic.toml")
    path = tmp_path / "job.toml"
    path.write_text(JOB.format(comp=comp, gain=gain, init=init, drive=drive, speeds=speeds))
    return path


def test_a_job_runs_its_drive_file_machine_timing_controller_and_sensors(tmp_path):
    job = load_job(_job(tmp_path))
    f = read_drive(TEKNIC)
    assert job.drive.machine == "teknic_m2310p" and job.drive.drive_file.machine.p == 4
    assert job.values["ts"] == pytest.approx(5e-5, rel=1e-15)  # the observer runs at the drive's 20 kHz
    d = job_drive(job.drive)
    assert float(d.ts) == pytest.approx(5e-5, rel=1e-15) and float(d.inverter.udc) == 24.0
    assert float(d.foc.kp_w) == pytest.approx(float(f.drive.foc.kp_w), rel=1e-15)
    assert float(d.foc.i_max) == pytest.approx(1.5 * 2**0.5 * 5.020458146424486, rel=1e-12)
    # the result keeps the drive inline, so it reads the same drive wherever it moves
    raw = job.raw["drive"]
    assert "file" not in raw and raw["name"] == "teknic_m2310p" and raw["inverter"]["u_dc"] == 24.0
    again = parse_job(json.loads(json.dumps(job.raw)))
    assert again.drive.machine == "teknic_m2310p" and again.values["ts"] == job.values["ts"]


def test_the_same_tables_inline_give_the_same_drive(tmp_path):
    text = TEKNIC.read_text().split("\n[machine]", 1)[1]
    inline = "[drive.machine]" + text.replace("\n[inverter]", "\n[drive.inverter]").replace(
        "\n[sensors]", "\n[drive.sensors]"
    ).replace("\n[control]", "\n[drive.control]")
    path = _job(tmp_path, drive='loop = "sensorless"\n' + inline)
    job = load_job(path)
    a, b = job_drive(job.drive), job_drive(load_job(_job(tmp_path)).drive)
    assert float(a.foc.kp_d) == float(b.foc.kp_d) and float(a.ts) == float(b.ts)
    assert float(job.drive.drive_file.sensors.i_noise) > 0  # the ADC's quantization: the scenarios' sensors


def test_the_speed_grid_is_checked_against_the_files_speed_limit(tmp_path):
    with pytest.raises(
        JobError, match=r"^scenarios\.grid\.speed_rpm\[0\]: must be in \[1, 5172\] r/min on teknic_m2310p"
    ):
        load_job(_job(tmp_path, speeds="6000.0"))


def test_a_bad_drive_table_is_one_line_naming_the_field(tmp_path):
    with pytest.raises(JobError, match=r"^drive\.file: 'missing\.toml': drive file: cannot read"):
        load_job(_job(tmp_path, drive='file = "missing.toml"'))
    with pytest.raises(JobError, match=r"^drive\.machine: must be one of ipmsm002, spmsm000"):
        load_job(_job(tmp_path, drive='machine = "teknic"'))
    with pytest.raises(JobError, match=r"^drive\.file: give a drive file, a shipped machine or the tables inline"):
        load_job(_job(tmp_path, drive='file = "teknic.toml"\nmachine = "spmsm000"'))
    (tmp_path / "bad.toml").write_text(TEKNIC.read_text().replace("Ld = 0.0002 ", "Ld = -0.0002 "))
    with pytest.raises(JobError, match=r"^drive\.file: 'bad\.toml': machine\.Ld must be in \[1e-08, 10\] H"):
        load_job(_job(tmp_path, drive='file = "bad.toml"'))


def test_a_flux_observer_runs_on_a_salient_machine_through_the_active_flux(tmp_path):
    """000's observers bind L̂q on a salient machine (jaxobs.observers.flux, "Salient machines"): a job on a
    salient drive file loads, as the LESOs' always did."""
    salient = TEKNIC.read_text().replace("Lq = 0.0002 ", "Lq = 0.0003 ")
    (tmp_path / "ipm.toml").write_text(salient)
    load_job(_job(tmp_path, drive='file = "ipm.toml"', comp="SOIFO", gain="k", init=1.4))
    load_job(_job(tmp_path, comp="SOIFO", gain="k", init=1.4))
    load_job(_job(tmp_path, drive='file = "ipm.toml"'))


def test_the_registry_states_which_machines_each_component_supports():
    ipm, spm = bench_machine("ipmsm002"), bench_machine("spmsm000")
    dual = dual_ipmsm_paper002()
    for name, e in REGISTRY.items():
        if not e.machines:
            assert e.refusal(spm) is not None  # the grid FLLs run on no drive
            continue
        assert e.refusal(spm) is None, name
        assert (e.refusal(ipm) is None) == e.salient, name
        assert (e.refusal(dual) is None) == e.dual, name
    assert REGISTRY["CLESO"].dual and not REGISTRY["SOIFO"].dual and REGISTRY["LPFFlux"].salient


def test_tune_envelope_and_export_run_on_a_users_drive_file(tmp_path, capsys):
    job = _job(tmp_path)
    out = tmp_path / "out"
    assert main(["tune", str(job), "--out", str(out), "--quiet"]) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["machine"] == "teknic_m2310p" and res["job"]["drive"]["inverter"]["f_sample_hz"] == 20000.0
    # the result moved away from its drive file still reads it (kept inline); --drive names one explicitly
    moved = tmp_path / "moved"
    moved.mkdir()
    shutil.copy(out / "result.json", moved / "result.json")
    assert main(["envelope", str(moved / "result.json"), "--check", "--speeds", "2", "--loads", "1"]) == 0
    assert main(["envelope", str(moved / "result.json"), "--drive", str(TEKNIC), "--check", "--speeds", "2",
                 "--loads", "1"]) == 0  # fmt: skip
    assert "teknic_m2310p" in capsys.readouterr().out
    exp = tmp_path / "export"
    assert (
        main(["export", str(moved / "result.json"), "--out", str(exp), "--steps", "10000", "--check", "--quiet"]) == 0
    )
    text = capsys.readouterr().out
    coeffs = json.loads((exp / "coefficients.json").read_text())
    assert coeffs["ts"] == pytest.approx(5e-5, rel=1e-7)
    assert "#define JX_TS 5e-05f" in (exp / "observer.h").read_text()
    assert "drive file teknic_m2310p" in coeffs["golden"]["signal"]
    if shutil.which("cc") is not None:
        assert "OK" in text


STUDY = """
[study]
kind = "drive"
horizon = 0.05
[drive]
file = "teknic.toml"
[designs.cf]
closed_form = "CLESO"
[axes]
speed_rpm = [{speed}]
"""


def test_a_drive_study_runs_the_users_drive_file(tmp_path):
    shutil.copy(TEKNIC, tmp_path / "teknic.toml")
    st = tmp_path / "s.toml"
    st.write_text(STUDY.format(speed="1000.0"))
    spec = load_study(st)
    assert spec.provenance["machine"].startswith("teknic_m2310p:")
    assert int(spec.family.machine.p) == 4 and float(spec.family.drive.ts) == pytest.approx(5e-5, rel=1e-15)
    assert float(spec.designs["cf"].ts) == pytest.approx(5e-5, rel=1e-15)  # the closed form at the drive's period
    st.write_text(STUDY.format(speed="6000.0"))
    with pytest.raises(JobError, match=r"^axes\.speed_rpm\[0\]: must be in \[1, 5172\] r/min on teknic_m2310p"):
        load_study(st)
    st.write_text(STUDY.format(speed="1000.0").replace("[study]\n", '[study]\nmachine = "ipmsm002"\n'))
    with pytest.raises(JobError, match=r"^study\.machine: give study\.machine or the \[drive\] file"):
        load_study(st)


@pytest.mark.repro  # about 6 minutes on 2 loaded cores (the envelope's compiles and twelve 3 s runs): `make test-repro`
def test_verdicts_on_a_users_drive_agree_with_pulse_simulations():
    """The C-LESO closed form on the Teknic drive file (not a paper's machine): at each low-speed point of its map
    (40, 80, 200 r/min × 0 and half rated torque) the envelope's verdict `holds` agrees with a 3 s simulation
    pulsed +2 % and one pulsed −2 % (held: the late speed deviation under 1 % and not above the early one).
    Measured: holds at 80 and 200 r/min loaded, nowhere unloaded or at 40 r/min, both directions alike."""
    from pulses import pulse_held

    import jaxobs
    from jaxobs.analysis.envelope import envelope
    from jaxobs.drive import load_drive
    from jaxobs.scenarios.families import bind_observer

    par, drive = load_drive(TEKNIC)
    cf = registered("cleso").cls.closed_form(ts=drive.ts)
    speeds, loads = [40.0, 80.0, 200.0], [0.0, float(par.T_rated) / 2]
    ds = envelope({"cf": cf}, machine=par, drive=drive, speeds_rpm=speeds, loads_nm=loads)
    points = [(s, ld) for s in speeds for ld in loads]
    foc = drive.foc.bind(par, drive.inverter.u_max)
    horizon = max(3.0, float(ds.attrs["horizon"]))

    def held(height):
        system = lambda obs, sc: jaxobs.drive.ClosedLoop(drive, bind_observer(obs, sc), sc)  # noqa: E731
        return pulse_held(system, {"cf": cf}, par, foc, points, height=height, horizon=horizon)["cf"]

    verdict = [int(ds["holds"].sel(design="cf", speed_rpm=s, load_nm=ld)) == 1 for s, ld in points]
    assert held(0.02).tolist() == verdict and held(-0.02).tolist() == verdict, verdict
    assert verdict == [False, False, False, True, False, True]
