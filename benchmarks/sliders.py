"""A gain slider's move as the user sees it: notebooks/05_gain_sliders.ipynb in a real kernel, a slider moved by the
message a browser sends, timed until the kernel has sent the new picture.

    python -m benchmarks.sliders [--moves 20] [--before REV] [--json F]

Two ipykernel kernels run the notebook's code cells, top to bottom: one the current tree's notebook and callback
(``notebooks/gain_sliders.py``), the other both files as they were at ``--before`` (default: the commit before the
redraw was made cheap), each in a folder of its own. Then the k slider is moved ``--moves`` times in each kernel,
the two interleaved, the same values in both (after 2 moves each, not timed): this process sends the ``comm_msg``
a browser sends when a slider is dragged (``{"method": "update", "state": {"value": k}}`` to the slider's widget)
and waits for the kernel's ``idle`` status on that message. Timed per move:

- wall: from sending the message to the kernel's ``idle``: the widget's value set, the observer called (simulate,
  redraw) and the display message sent (before: ``display(fig)`` into an ``Output``, the inline backend's PNG of
  the figure; after: the ``Image`` widget's new bytes);
- CPU: the kernel process's CPU time over the move, all its threads (``/proc/PID/task/*/schedstat``: the callback,
  the encoding, the kernel's sending threads).

What the browser then does with the picture (decode and paint, a few ms for a PNG this size) is not in it.  Also
printed: the bytes of picture each move sends, and the XLA compilations during the timed moves (JAX's
``/jax/core/compile/backend_compile_duration`` events in each kernel; 0 when a move recompiles nothing).  The load
average is read at the start and the end. Last, each kernel times the callback alone, ``ui(k, lam)`` at the same
values with no widget and no display (``time.process_time``), the part tests used to hold to a budget.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK, CALLBACK = "notebooks/05_gain_sliders.ipynb", "notebooks/gain_sliders.py"
BEFORE = "37755be"  # main before the slider's redraw was made cheap: full render, display(fig) into an Output
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
WARMUP = 2
# after the notebook's cells: count XLA compilations from here on, and name the k slider's widget
PROBE = f"""
import jax.monitoring as _monitoring
_compiles = []
_monitoring.register_event_duration_secs_listener(
    lambda name, secs, **kw: _compiles.append(secs) if name == {COMPILE_EVENT!r} else None
)
print(k.model_id)
"""


def _files(rev: str | None) -> dict[str, str]:
    """The notebook and its callback at ``rev`` (``None``: the working tree)."""
    if rev is None:
        return {p: (ROOT / p).read_text() for p in (NOTEBOOK, CALLBACK)}
    return {
        p: subprocess.check_output(["git", "show", f"{rev}:{p}"], cwd=ROOT, text=True) for p in (NOTEBOOK, CALLBACK)
    }


def _cpu_s(pid: int) -> float:
    """A process's CPU seconds, summed over its threads (``/proc/PID/task/*/schedstat``: nanoseconds on a CPU; the
    user + system ticks of ``/proc/PID/stat`` count in 10 ms)."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            total += int((task / "schedstat").read_text().split()[0])
        except (FileNotFoundError, ProcessLookupError):  # a thread that ended meanwhile
            continue
    return total * 1e-9


class Kernel:
    """An ipykernel kernel running a notebook's code cells in ``folder`` (where its callback module lies)."""

    def __init__(self, name: str, folder: Path, cells: list[str]):
        from jupyter_client.manager import KernelManager

        self.name = name
        self.km = KernelManager(kernel_name="python3")
        self.km.start_kernel(cwd=str(folder), env={**os.environ, "PYTHONPATH": str(ROOT)})
        self.kc = self.km.client()
        self.kc.start_channels()
        self.kc.wait_for_ready(timeout=120)
        provisioner = self.km.provisioner
        assert provisioner is not None
        self.pid = int(provisioner.process.pid)  # type: ignore[attr-defined]
        for source in cells:
            self.execute(source)
        self.slider = self.execute(PROBE).strip().splitlines()[-1]

    def execute(self, source: str, timeout: float = 900) -> str:
        """Run ``source``; its stdout. Raises RuntimeError with the traceback on an error."""
        msg_id = self.kc.execute(source)
        out: list[str] = []
        while True:
            msg = self.kc.get_iopub_msg(timeout=timeout)
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            kind, content = msg["msg_type"], msg["content"]
            if kind == "stream" and content["name"] == "stdout":
                out.append(content["text"])
            elif kind == "error":
                raise RuntimeError(f"{self.name}: {content['ename']}: {content['evalue']}")
            elif kind == "status" and content["execution_state"] == "idle":
                return "".join(out)

    def move(self, value: float, timeout: float = 120) -> dict:
        """Move the k slider to ``value`` as a browser does; wall and CPU seconds until the kernel is idle again,
        and the bytes of picture it sent."""
        data = {"method": "update", "state": {"value": value}, "buffer_paths": []}
        msg = self.kc.session.msg("comm_msg", {"comm_id": self.slider, "data": data})
        c0, t0 = _cpu_s(self.pid), time.perf_counter()
        self.kc.shell_channel.send(msg)
        png = 0
        while True:
            try:
                m = self.kc.get_iopub_msg(timeout=timeout)
            except queue.Empty:
                raise RuntimeError(f"{self.name}: no reply to a move in {timeout} s") from None
            if m["parent_header"].get("msg_id") != msg["header"]["msg_id"]:
                continue
            kind, content = m["msg_type"], m["content"]
            if kind == "display_data" and "image/png" in content["data"]:
                png += len(content["data"]["image/png"]) * 3 // 4  # base64
            elif kind == "comm_msg" and m.get("buffers"):
                png += sum(len(b) for b in m["buffers"])
            elif kind == "error":
                raise RuntimeError(f"{self.name}: {content['ename']}: {content['evalue']}")
            elif kind == "status" and content["execution_state"] == "idle":
                return {"wall_s": time.perf_counter() - t0, "cpu_s": _cpu_s(self.pid) - c0, "png_bytes": png}

    def compiles(self) -> int:
        """XLA compilations since the probe ran."""
        return int(self.execute("print(len(_compiles))").strip())

    def callback(self, values: list[float]) -> dict:
        """The callback alone, ``ui(k, lam)`` called in the kernel (no widget, no display): median wall and CPU (the
        kernel's ``time.process_time``) over ``values`` of k, and the class of the figure's canvas."""
        code = f"""
import time as _t, json as _j, numpy as _np
_w, _c = [], []
for _k in {values!r}:
    _c0, _w0 = _t.process_time(), _t.perf_counter()
    ui(_k, lam.value)
    _c.append(_t.process_time() - _c0)
    _w.append(_t.perf_counter() - _w0)
print(_j.dumps({{"median_wall_s": float(_np.median(_w)), "median_cpu_s": float(_np.median(_c)),
                "canvas": type(ui.fig.canvas).__name__}}))
"""
        return json.loads(self.execute(code).strip().splitlines()[-1])

    def close(self) -> None:
        self.kc.stop_channels()
        self.km.shutdown_kernel(now=True)


def _cells(notebook: str) -> list[str]:
    return [c["source"] if isinstance(c["source"], str) else "".join(c["source"]) for c in _code(notebook)]


def _code(notebook: str) -> list[dict]:
    return [c for c in json.loads(notebook)["cells"] if c["cell_type"] == "code"]


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def measure(moves: int = 20, before: str = BEFORE) -> dict:
    """Both kernels' moves, interleaved; per side the samples, their medians and the compilations during them."""
    values = [round(float(v), 2) for v in np.linspace(0.4, 1.6, moves + WARMUP)]  # the slider's 0.01 steps
    result: dict = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "uptime_start": _uptime(),
        "load_start": os.getloadavg(),
        "moves": moves,
        "before_rev": before,
    }
    kernels: list[Kernel] = []
    with tempfile.TemporaryDirectory() as tmp:
        try:
            for name, rev in (("before", before), ("after", None)):
                files = _files(rev)
                folder = Path(tmp) / name
                (folder / "notebooks").mkdir(parents=True)
                for path, text in files.items():
                    (folder / path).write_text(text)
                t0 = time.perf_counter()
                kernels.append(Kernel(name, folder / "notebooks", _cells(files[NOTEBOOK])))
                result[f"{name}_setup_s"] = time.perf_counter() - t0
            samples: dict[str, list[dict]] = {k.name: [] for k in kernels}
            for i, v in enumerate(values):
                for k in kernels:
                    s = k.move(v)
                    if i >= WARMUP:
                        samples[k.name].append(s)
            for k in kernels:
                rows = samples[k.name]
                result[k.name] = {
                    "wall_s": [r["wall_s"] for r in rows],
                    "cpu_s": [r["cpu_s"] for r in rows],
                    "png_bytes": [r["png_bytes"] for r in rows],
                    "median_wall_s": float(np.median([r["wall_s"] for r in rows])),
                    "median_cpu_s": float(np.median([r["cpu_s"] for r in rows])),
                    "compiles_during_moves": k.compiles(),
                    "callback": k.callback(values[WARMUP:]),
                }
        finally:
            for k in kernels:
                k.close()
    result["uptime_end"], result["load_end"] = _uptime(), os.getloadavg()
    return result


def table(r: dict) -> str:
    """The result as text: one row a side, then the ratio and the load."""
    lines = [
        f"gain-slider move, displayed (comm_msg -> kernel idle), {r['moves']} moves each, interleaved; {r['date']}, "
        f"{os.cpu_count()} CPUs",
        f"before = {r['before_rev']} (full render, display(fig) into an Output); after = this tree "
        "(blitted redraw, Image widget)",
        "",
        f"{'':8}{'median wall':>13}{'median CPU':>12}{'wall range':>20}{'PNG bytes':>11}{'compiles':>10}",
    ]
    for side in ("before", "after"):
        s = r[side]
        lo, hi = min(s["wall_s"]) * 1e3, max(s["wall_s"]) * 1e3
        lines.append(
            f"{side:8}{s['median_wall_s'] * 1e3:>10.0f} ms{s['median_cpu_s'] * 1e3:>9.0f} ms"
            f"{f'{lo:.0f}-{hi:.0f} ms':>20}{int(np.median(s['png_bytes'])):>11}{s['compiles_during_moves']:>10}"
        )
    b, a = r["before"], r["after"]
    lines += [
        "",
        "the callback alone, ui(k, lam) in the kernel, no display: "
        + ", ".join(
            f"{side} {r[side]['callback']['median_wall_s'] * 1e3:.0f} ms wall, "
            f"{r[side]['callback']['median_cpu_s'] * 1e3:.0f} ms CPU"
            for side in ("before", "after")
        ),
        "the figure's canvas in the kernel: "
        + ", ".join(f"{side} {r[side]['callback']['canvas']}" for side in ("before", "after"))
        + (
            " (FigureCanvasBase: the inline backend closed pyplot's figure after its cell, and a closed figure's "
            "draw() renders nothing; the display rendered it)"
            if "FigureCanvasBase" in {r[side]["callback"]["canvas"] for side in ("before", "after")}
            else ""
        ),
        f"after / before: wall {a['median_wall_s'] / b['median_wall_s']:.3f}, "
        f"CPU {a['median_cpu_s'] / b['median_cpu_s']:.3f}",
        f"setup (kernel start, the notebook's cells, the first compile): before {r['before_setup_s']:.0f} s, "
        f"after {r['after_setup_s']:.0f} s",
        f"start: {r['uptime_start']}",
        f"end:   {r['uptime_end']}",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.sliders", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--moves", type=int, default=20, help="timed moves per side (default 20, after 2 untimed)")
    p.add_argument("--before", default=BEFORE, help=f"the commit to compare with (default {BEFORE})")
    p.add_argument("--json", help="also write the result to this file")
    a = p.parse_args(argv)
    if not 1 <= a.moves <= 1000:
        p.error(f"--moves must be in [1, 1000], got {a.moves}")
    r = measure(a.moves, a.before)
    print(table(r))
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
