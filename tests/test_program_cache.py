"""The program cache can only make a run faster (jaxobs.ProgramCache, jaxobs.kept_jit): every file planted in its
folder (another job's program, a flipped bit, a FIFO, a folder, a symlink, another program of the same job, a
program that takes other inputs) is refused in one line naming the folder, the program is traced again and its entry
replaced, and the numbers are the clean run's; a folder others may write to and the user does not own is not used."""

import os
import signal
import stat

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import export

import jaxobs
from jaxobs.runtime import programs as _traced

X = jnp.linspace(-1.0, 2.0, 11)


def _job(step: float):
    """Two jobs that differ only in a constant (a frequency step, say): their programs have the same shapes."""

    def value(x, n):
        return {"y": jnp.sin(x * step) + n, "s": (jnp.cumsum(x) * step,)}

    def response(x, n):  # another program of the same job, of the same input and output shapes
        return {"y": jnp.cos(x * step) - n, "s": (jnp.cumprod(x) + step,)}

    return value, response


def _clean(fn, n=2):
    return jax.device_get(eqx.filter_jit(fn)(X, n))


def _same(a, b) -> bool:
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    return jax.tree.structure(a) == jax.tree.structure(b) and all(
        np.array_equal(np.asarray(u), np.asarray(v)) for u, v in zip(la, lb)
    )


@pytest.fixture
def folder(tmp_path):
    before = _traced.program_cache()
    yield tmp_path / "traced"
    _traced.set_program_cache(before)


def _process(folder) -> jaxobs.ProgramCache:
    """What a new process sees: a cache on ``folder`` with nothing in memory."""
    cache = jaxobs.ProgramCache(folder)
    jaxobs.set_program_cache(cache)
    return cache


def _entries(folder) -> dict:
    return {p.name: p for p in folder.iterdir()}


def _kept_once(folder, fn) -> str:
    """Run ``fn`` kept in a fresh process; the name of the entry it wrote."""
    before = set(_entries(folder)) if folder.exists() else set()
    _process(folder)
    jaxobs.kept_jit(fn)(X, 2)
    (new,) = set(_entries(folder)) - before
    return new


def _warned_once(capsys, folder) -> str:
    err = capsys.readouterr().err
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and str(folder) in lines[0] and lines[0].startswith("jaxobs: warning: program cache"), err
    return lines[0]


def _no_temp(folder):
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp") or p.name.startswith(".")]


def test_a_read_back_program_gives_the_clean_numbers_and_a_later_process_does_not_trace(folder, capsys):
    value = _job(2.0)[0]
    name = _kept_once(folder, value)
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    _process(folder)
    kept = jaxobs.kept_jit(value)
    assert _same(kept(X, 2), _clean(value)) and list(_entries(folder)) == [name]
    # another static value (n) or shape: another program
    assert _same(kept(X, 3), _clean(value, 3)) and len(_entries(folder)) == 2
    assert capsys.readouterr().err == ""


def test_another_jobs_program_of_the_same_shapes_is_not_run(folder, capsys):
    """The swap: the second job's program copied over the first's name; the first job gives its own numbers."""
    first, second = _job(2.0)[0], _job(3.0)[0]
    a, b = _kept_once(folder, first), _kept_once(folder, second)
    assert a != b  # the constant is in the key
    (folder / a).write_bytes((folder / b).read_bytes())
    _process(folder)
    got = jaxobs.kept_jit(first)(X, 2)
    assert _same(got, _clean(first)) and not _same(got, _clean(second))
    assert "another program's key" in _warned_once(capsys, folder)
    _process(folder)  # the entry was replaced: a later process reads it without a word
    assert _same(jaxobs.kept_jit(first)(X, 2), _clean(first)) and capsys.readouterr().err == ""
    _no_temp(folder)


def test_another_program_of_the_same_job_in_the_slot_is_recomputed(folder, capsys):
    value, response = _job(2.0)
    a, b = _kept_once(folder, value), _kept_once(folder, response)
    (folder / a).write_bytes((folder / b).read_bytes())
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    _warned_once(capsys, folder)
    _no_temp(folder)


@pytest.mark.parametrize("where", ["header", "program", "end"])
def test_a_bit_flip_is_recomputed_with_one_line(folder, capsys, where):
    value = _job(2.0)[0]
    name = _kept_once(folder, value)
    data = bytearray((folder / name).read_bytes())
    i = {"header": 40, "program": len(data) // 2, "end": len(data) - 1}[where]
    data[i] ^= 0x10
    (folder / name).write_bytes(bytes(data))
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    _warned_once(capsys, folder)
    _no_temp(folder)
    assert (folder / name).read_bytes() != bytes(data)  # replaced


def test_a_fifo_in_place_does_not_hang(folder, capsys):
    value = _job(2.0)[0]
    name = _kept_once(folder, value)
    (folder / name).unlink()
    os.mkfifo(folder / name)
    _process(folder)
    signal.signal(signal.SIGALRM, lambda *a: pytest.fail("the cache read hung on a FIFO"))
    signal.alarm(60)
    try:
        got = jaxobs.kept_jit(value)(X, 2)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
    assert _same(got, _clean(value))
    assert "not a regular file" in _warned_once(capsys, folder)
    assert (folder / name).is_file()  # replaced by the program
    _no_temp(folder)


def test_a_folder_in_place_leaves_no_temp_file(folder, capsys):
    value = _job(2.0)[0]
    name = _kept_once(folder, value)
    (folder / name).unlink()
    (folder / name).mkdir()
    (folder / name / "inside").write_text("x")
    for _ in range(2):  # two processes: each recomputes, neither leaves its temp file
        _process(folder)
        assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
        _warned_once(capsys, folder)
        _no_temp(folder)
    assert (folder / name / "inside").read_text() == "x"


def test_a_symlink_in_place_is_not_read_through(folder, tmp_path, capsys):
    value, response = _job(2.0)
    name = _kept_once(folder, value)
    outside = tmp_path / "outside.jaxexport"
    outside.write_bytes((folder / name).read_bytes())  # even a valid program is not read through a link
    (folder / name).unlink()
    (folder / name).symlink_to(outside)
    before = outside.read_bytes()
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    _warned_once(capsys, folder)
    assert not (folder / name).is_symlink() and outside.read_bytes() == before
    _no_temp(folder)


def test_a_program_that_takes_other_inputs_under_the_right_key_is_recomputed(folder, capsys):
    """The entry's key and digest are right, but the program takes other inputs: the deserialized program is
    checked against the call."""
    value = _job(2.0)[0]
    cache = _process(folder)
    name = _traced._key(value, (X, 2))
    other = export.export(jax.jit(lambda a, b: {"y": a + b, "s": (a * b,)}))(X, X)  # two inputs, not one
    assert cache.enabled  # the folder made
    cache._write(folder / f"{name}.jaxexport", bytes(other.serialize()))
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    assert "takes other inputs" in _warned_once(capsys, folder)
    _process(folder)  # replaced: read back without a word
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value)) and capsys.readouterr().err == ""
    _no_temp(folder)


def test_an_entry_over_the_size_cap_is_recomputed(folder, capsys, monkeypatch):
    value = _job(2.0)[0]
    _kept_once(folder, value)
    monkeypatch.setattr(_traced, "MAX_BYTES", 64)
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    assert "at most 64 bytes" in _warned_once(capsys, folder)


@pytest.mark.parametrize("keep", [0, 10, 22 + 64, 22 + 128])
def test_a_truncated_entry_is_recomputed(folder, capsys, keep):
    """Cut in its magic, its key, its digest or at its program's start (a full disk, a copy cut short)."""
    value = _job(2.0)[0]
    name = _kept_once(folder, value)
    (folder / name).write_bytes((folder / name).read_bytes()[:keep])
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    assert "corrupt" in _warned_once(capsys, folder)


def test_one_line_for_several_problems(folder, capsys):
    value, response = _job(2.0)
    for fn in (value, response):
        (folder / _kept_once(folder, fn)).write_bytes(b"garbage")
    _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    assert _same(jaxobs.kept_jit(response)(X, 2), _clean(response))
    _warned_once(capsys, folder)


def test_a_folder_others_write_to_and_the_user_does_not_own_is_not_used(folder, capsys, monkeypatch):
    folder.mkdir(mode=0o700)
    folder.chmod(0o777)
    _process(folder)
    value = _job(2.0)[0]
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))  # the user's own: used
    assert len(_entries(folder)) == 1 and capsys.readouterr().err == ""
    uid = os.getuid()
    monkeypatch.setattr(_traced.os, "getuid", lambda: uid + 1)  # now another user's
    for p in folder.iterdir():
        p.unlink()
    cache = _process(folder)
    assert _same(jaxobs.kept_jit(value)(X, 2), _clean(value))
    assert not cache.enabled and not list(folder.iterdir())
    assert "writable by others: not used" in _warned_once(capsys, folder)
    folder.chmod(0o755)  # another user's, but only theirs to write: used (read back, as a shared read-only cache)
    assert _process(folder).enabled


def test_the_key_covers_what_reaches_the_program(monkeypatch):
    """What reaches a program is in its key: a closure's array by value, a static field, an input's dtype, an
    object's kept_fields, which of two lambdas of one line, the source of the defining module and of jaxobs; what
    the key cannot name (an object of unknown kind, a function with no source file) is not kept."""

    class Gain(eqx.Module):
        k: jax.Array
        n: int = eqx.field(static=True)

    def key(fn, *args):
        return _traced._key(fn, args)

    def with_constant(c):
        return lambda x: x * c

    a, b = jnp.asarray([1.0, 2.0]), jnp.asarray([1.0, 3.0])
    assert key(with_constant(a), X) != key(with_constant(b), X)  # a closure's arrays are constants: by value
    f = lambda g, x: g.k * x  # noqa: E731
    assert key(f, Gain(a, 1), X) == key(f, Gain(b, 1), X)  # an input's arrays: by shape and dtype
    assert key(f, Gain(a, 1), X) != key(f, Gain(a, 2), X)  # a static field
    assert key(f, Gain(a, 1), X) != key(f, Gain(a.astype(jnp.float32), 1), X)
    assert key(f, Gain(a, 1), X) != key(f, Gain(a, 1), X[:5])  # a shape
    twice, thrice = (lambda x: x * 2), (lambda x: x * 3)  # noqa: E731  (one line, one qualified name)
    assert key(twice, X) != key(thrice, X)
    assert key(f, {"a": 1, "b": X, "c": 1}) != key(f, {"a": 1, "b": X, "c": 2})  # every item (none taken for another)
    assert key(f, [(1, 2), (3, 4)], X) != key(f, [(1, 2), (3, 5)], X)
    assert key(f, (twice, thrice), X) != key(f, (twice, twice), X)
    before = key(f, Gain(a, 1), X)
    for top in ("jaxobs", __name__.split(".")[0]):  # jaxobs edited; the test's own file edited
        with monkeypatch.context() as m:
            m.setitem(_traced._memo, top, _traced._memo[top] + "-edited")
            assert key(f, Gain(a, 1), X) != before
    assert key(f, Gain(a, 1), X) == before

    class Holder:
        kept_fields = ("c",)

        def __init__(self, c):
            self.c = c

        def run(self, x):
            return x * self.c

    assert key(Holder(a).run, X) != key(Holder(b).run, X)

    class Opaque:
        def run(self, x):
            return x

    with pytest.raises(ValueError):
        key(Opaque().run, X)
    typed = {"__name__": "an_interactive_session"}
    exec("def typed_in(x):\n    return x * 2", typed)  # no file holds it
    with pytest.raises(ValueError, match="no source file"):
        key(typed["typed_in"], X)


def test_what_the_key_cannot_name_runs_as_a_plain_jit(folder):
    typed = {"__name__": "an_interactive_session", "jnp": jnp}
    exec("def typed_in(x, n):\n    return {'y': jnp.sin(x) + n}", typed)
    _process(folder)
    assert _same(jaxobs.kept_jit(typed["typed_in"])(X, 2), _clean(typed["typed_in"]))
    assert not folder.exists() or not list(folder.iterdir())
