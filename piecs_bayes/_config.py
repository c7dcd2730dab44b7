"""Process-wide JAX settings, applied once, by the first subpackage that computes.

Every subpackage that uses JAX (geometry, io, gcode, fit, compensate,
uncertainty, jobs, export) imports this module first; the package root and the
CLI's argument parsing do not, so ``piecs-bayes --help`` does not import JAX
(tests/cli/test_startup.py).

float64 is switched on before any array is made: micrometres on a 100 mm part
need it. A persistent compilation cache in the user's cache directory lets a
second CLI run reuse the compiled fits (set ``PIECS_BAYES_NO_CACHE=1`` to opt out).
Every compilation is cached, however short (threshold 0 s): a `fit` run compiles
~50 small programs of 0.03-0.1 s each (eager operations, per-feature helpers)
that the default 1 s (or 0.2 s) threshold left out, ~2 s of a warm run.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.machinery
import importlib.metadata
import importlib.util
import json
import os
import sys
import threading
import time
from pathlib import Path

# ------------------------------------------------------------------ import costs
# Two costs every computing process paid for work it never asks for (jax 0.10.2):
# - `import jax` looks for a ROCm plugin by parsing the metadata of every installed
#   distribution (0.13 s of the 158 of this environment; jax-ml/jax#37879). The scan
#   gets only the distributions whose name, read from their folder, can be one
#   (`_rocm_scan_narrowed`); jax's loop takes nothing else.
# - the first call of a `jax.export`ed program (the kept traces) initialises jaxlib's
#   LAPACK handlers, which imports the two Cython modules of SciPy's BLAS and LAPACK
#   function tables and so the whole of scipy.linalg (0.14 s). `load_lapack_tables`
#   initialises them first from those two modules loaded alone (12 ms).
# Both fall back to what jax does itself wherever they do not apply.

_ROCM_SCAN_MODULE = "jax._src.numpy.array_constructors"


def _may_be_rocm_plugin(dist) -> bool:
    """Whether `dist` can be a `jax-rocm*-plugin`, judged from its folder's name where
    the distribution gives it without reading its metadata (else True: read it)."""
    name = getattr(dist, "_normalized_name", None)
    return not isinstance(name, str) or name.startswith("jax_rocm")


@contextlib.contextmanager
def _rocm_scan_narrowed():
    """`importlib.metadata.distributions()`, while jax is imported, lists only the
    distributions that can be a ROCm plugin to jax's scan, everything to any other caller."""
    everything = importlib.metadata.distributions

    def distributions(**kwargs):
        found = everything(**kwargs)
        if sys._getframe(1).f_globals.get("__name__") != _ROCM_SCAN_MODULE:
            return found
        return (d for d in found if _may_be_rocm_plugin(d))

    importlib.metadata.distributions = distributions
    try:
        yield
    finally:
        importlib.metadata.distributions = everything


def load_lapack_tables() -> None:
    """Initialise jaxlib's LAPACK handlers from `scipy.linalg.cython_blas` and
    `cython_lapack` loaded alone, without scipy.linalg's own imports; once a process.

    The two modules are then taken out of `sys.modules` where importing them again
    gives the same module objects (single-phase extension modules, as SciPy builds
    them), so that a later `import scipy.linalg` sets them up as its own. Where they
    cannot be found or loaded alone, nothing is done: jaxlib imports them itself.
    A module enters `sys.modules` only once made (another thread's import never sees
    it half made); concurrent callers wait for the first."""
    global _lapack_ready
    if _lapack_ready:
        return
    with _lapack_lock:
        if not _lapack_ready and "scipy.linalg.cython_lapack" not in sys.modules:
            _load_lapack_tables()
        _lapack_ready = True


def _load_lapack_tables() -> None:
    """The loading and initialisation of `load_lapack_tables` (under its lock)."""
    loaded: dict = {}
    try:
        import scipy

        folder = Path(scipy.__file__).parent / "linalg"
        for name in ("cython_blas", "cython_lapack"):
            full = f"scipy.linalg.{name}"
            if full in sys.modules:
                continue
            path = next(
                p
                for suffix in importlib.machinery.EXTENSION_SUFFIXES
                if (p := folder / f"{name}{suffix}").is_file()
            )
            loader = importlib.machinery.ExtensionFileLoader(full, str(path))
            spec = importlib.util.spec_from_file_location(full, path, loader=loader)
            module = importlib.util.module_from_spec(spec)
            loader.exec_module(module)
            sys.modules[full] = module  # cython_lapack, made next, imports cython_blas
            loaded[full] = (loader, spec, module)
        from jax._src.lax.linalg import initialize_lapack

        initialize_lapack()
    except Exception:  # noqa: BLE001 - not found or not loadable alone: jaxlib imports them
        pass
    for full, (loader, spec, module) in loaded.items():
        if loader.create_module(spec) is module:  # imported again, the same object
            del sys.modules[full]


_lapack_ready = False
_lapack_lock = threading.Lock()


if "jax" in sys.modules:
    import jax
else:
    with _rocm_scan_narrowed():
        import jax

jax.config.update("jax_enable_x64", True)

# ------------------------------------------------------------------ dispatch
# On the CPU, JAX runs a program on a thread of its own and hands the result back
# (asynchronous dispatch): for the small programs this package calls in loops (emcee's
# log posterior per half-step, per-part kernels, the feedback replays) the handoff
# costs more than the program. Run in the calling thread: a 16-walker log posterior
# called and read back in 24 us against 100-130 us. Results are the same programs' and
# the same bits. Read when the CPU backend is made (the first array), after this
# import; a user's JAX_CPU_ENABLE_ASYNC_DISPATCH is kept.
if "JAX_CPU_ENABLE_ASYNC_DISPATCH" not in os.environ:
    jax.config.update("jax_cpu_enable_async_dispatch", False)


# ------------------------------------------------------------------ code generators
# XLA's CPU backend has two code generators for fused element-wise work: the MLIR
# fusion emitters (its default) and the older elemental emitter. On this package's
# programs the older compiles in two thirds of the time (an eager operation 19 ms
# against 32 ms, a robust solve 0.9 s against 1.6 s; `make test` builds in 274 s of
# its workers against 422 s) and runs as fast, except loops heavy in transcendental
# functions: the samplers' steps run 13 % slower. So a run compiles with the older,
# and the programs that run for long (the lockstep sampler) ask for the newer with
# `LONG_RUNNING`. Set only where the flag is known (jaxlib 0.10: an unknown XLA flag
# aborts the process) and not already chosen in XLA_FLAGS; the marker tells a child
# process (which inherits XLA_FLAGS) that the choice is ours, not the user's.
# Read when the backend starts (the first array), after this import.
_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
_MARK = "PIECS_BAYES_XLA_FLAGS"


def _choose_emitters() -> dict:
    import jaxlib

    flags = os.environ.get("XLA_FLAGS", "")
    if os.environ.get(_MARK) == _EMITTERS and _EMITTERS in flags.split():
        return {"xla_cpu_use_fusion_emitters": True}  # set by our parent process
    if "xla_cpu_use_fusion_emitters" in flags or not jaxlib.__version__.startswith("0.10."):
        return {}  # the user's choice, or a jaxlib this was not measured on
    os.environ["XLA_FLAGS"] = f"{flags} {_EMITTERS}".strip()
    os.environ[_MARK] = _EMITTERS
    return {"xla_cpu_use_fusion_emitters": True}


#: compiler options of programs that run long enough for their speed to outweigh
#: their compilation (`jax.stages.Lowered.compile(LONG_RUNNING)`); empty when the
#: run compiles everything alike
LONG_RUNNING: dict = _choose_emitters()


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "piecs_bayes" / "jax"


if not os.environ.get("PIECS_BAYES_NO_CACHE"):
    try:
        _dir = _cache_dir()
        _dir.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(_dir))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    except OSError:  # read-only home: run without the cache
        pass


# ------------------------------------------------------------------ arrays to the device
# jax 0.10's `jnp.asarray(x)` of a NumPy array or scalar (no dtype given) binds
# `lax.stage`, an identity that XLA compiles once per shape and dtype: ~200 of the
# programs a `make test` run built were these. A transfer compiles nothing.


def on_device(tree):
    """`tree` with every NumPy array and number transferred as it is (dtype kept, no
    compilation); JAX arrays, tracers and None pass through."""
    import numpy as np

    def put(x):
        if isinstance(x, jax.Array) or x is None:
            return x
        return jax.device_put(np.asarray(x))

    return jax.tree_util.tree_map(put, tree)


# ------------------------------------------------------------------ persisted traces
# The compilation cache skips XLA's compilation, not JAX's tracing of the Python
# function (seconds for the fit kernel). `persisted` keeps the traced program too,
# serialised with `jax.export` next to the compilation cache: a later process
# deserialises it (milliseconds) and compiles it from the compilation cache.


@functools.cache
def source_hash(*packages: str) -> str:
    """SHA-256 of the Python sources of `packages` (subpackages of piecs_bayes, what a
    trace runs); of every module when none is named. A trace of other sources is stale."""
    h = hashlib.sha256()
    root = Path(__file__).resolve().parent
    for top in packages or (".",):
        for p in sorted((root / top).rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _export_path(name: str, key, packages) -> Path | None:
    """Where the trace of `name` for `key` is kept; None when the cache is off."""
    if os.environ.get("PIECS_BAYES_NO_CACHE"):
        return None
    import jaxlib

    ident = repr((name, key, jax.__version__, jaxlib.__version__, jax.default_backend(),
                  bool(jax.config.jax_enable_x64), source_hash(*packages)))  # fmt: skip
    digest = hashlib.sha256(ident.encode()).hexdigest()[:32]
    return _cache_dir().parent / "export" / f"{name}-{digest}.bin"


#: persisted traces neither read nor written for this many days are removed when a
#: new trace is written (a stale one, of older sources or versions, is never read again)
EXPORT_MAX_AGE_DAYS = 30


def _prune_exports(folder: Path) -> None:
    """Remove the traces in `folder` unused for `EXPORT_MAX_AGE_DAYS` (best effort)."""
    cutoff = time.time() - EXPORT_MAX_AGE_DAYS * 86400.0
    for old in folder.glob("*.bin"):
        try:
            if old.stat().st_mtime < cutoff:
                old.unlink()
        except OSError:  # gone already, or not ours to remove
            pass


def persisted(name: str, key, build, packages: tuple[str, ...] = ()) -> tuple:
    """`(compiled function, meta)` of a traced program, kept across processes.

    `build()` returns `(jitted function, example arguments, meta)`; `meta` is JSON
    data known once traced (e.g. the layout of a packed result). The trace is kept
    as `jax.export` serialisation under the cache directory, named by `name` and a
    digest of `key` (what the trace depends on: static settings, shapes), the JAX
    and jaxlib versions, the backend and the sources of `packages` (the subpackages
    whose code the trace runs; default all: `source_hash`). A
    missing, unreadable or stale file is traced again (and rewritten); with
    ``PIECS_BAYES_NO_CACHE=1`` nothing is read or written. The function returned
    runs the exported program (the same on the first and later runs). A trace read
    is touched; writing one removes those unused for `EXPORT_MAX_AGE_DAYS`.
    """
    from jax import export

    load_lapack_tables()  # before an export or a call is lowered: they initialise LAPACK
    path = _export_path(name, key, packages)
    if path is not None and path.is_file():
        try:
            blob = path.read_bytes()
            n = int.from_bytes(blob[:8], "little")
            meta = json.loads(blob[8 : 8 + n].decode())
            exported = export.deserialize(bytearray(blob[8 + n :]))
            try:
                os.utime(path)  # in use: kept by `_prune_exports`
            except OSError:
                pass
            return jax.jit(exported.call), meta
        except Exception:  # noqa: BLE001 - stale or corrupt: trace again, below
            pass
    fn, args, meta = build()
    exported = export.export(fn)(*args)
    if path is not None:
        head = json.dumps(meta).encode()
        try:
            blob = len(head).to_bytes(8, "little") + head + bytes(exported.serialize())
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
            tmp.write_bytes(blob)
            os.replace(tmp, path)
            _prune_exports(path.parent)
        except (OSError, ImportError):  # read-only cache, or no flatbuffers: not kept
            pass
    return jax.jit(exported.call), meta


class KeptTrace:
    """`fn(*args)` run through a trace kept across processes (`persisted`), one per
    structure of the arguments (their tree, shapes and dtypes), named by `name` and
    `key`: all that the traced function computes from (hashable, with a repr that
    says all of it, as for `persisted`). Arguments other than arrays (a Python number:
    weakly typed; a tracer: `fn` called inside another trace) go to `fn` itself.
    `compiled(*args)` gives the program for `args` compiled ahead of time, with
    `compiler_options` (e.g. `LONG_RUNNING`)."""

    def __init__(self, name: str, key, fn, compiler_options: dict | None = None):
        self.name, self.key, self.fn = name, key, fn
        self.compiler_options = compiler_options or None
        self._calls: dict = {}
        self._compiled: dict = {}

    def _call(self, args):
        """`(signature, jitted kept trace)` for `args`, or None where `fn` runs them."""
        import numpy as np

        leaves, tree = jax.tree_util.tree_flatten(args)
        if not all(isinstance(x, np.ndarray | jax.Array) for x in leaves) or any(
            isinstance(x, jax.core.Tracer) for x in leaves
        ):
            return None
        sig = (str(tree), tuple((tuple(x.shape), str(x.dtype)) for x in leaves))
        call = self._calls.get(sig)
        if call is None:
            specs = tree.unflatten([jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves])
            call = persisted(self.name, (self.key, sig), lambda: (self.fn, specs, {}))[0]
            self._calls[sig] = call
        return sig, call

    def __call__(self, *args):
        found = self._call(args)
        return self.fn(*args) if found is None else found[1](*args)

    def compiled(self, *args):
        """The program for arguments like `args` compiled now (`jax.stages.Compiled`,
        kept for later calls: it takes exactly these shapes and dtypes), or None
        where `fn` would run them itself."""
        found = self._call(args)
        if found is None:
            return None
        sig, call = found
        if sig not in self._compiled:
            self._compiled[sig] = call.lower(*args).compile(self.compiler_options)
        return self._compiled[sig]


class LazyModule:
    """A module imported on its first attribute access: `stats = LazyModule("scipy.stats")`
    keeps a run that never computes a quantile (`piecs-bayes fit`) from paying for
    scipy.stats at start-up (0.3-0.7 s of a 2.5 s warm run)."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        import importlib

        value = getattr(importlib.import_module(self._name), attr)
        # kept: later reads are plain attribute reads (through `import_module` they
        # cost ~7 us each, 0.6 s of the 87,000 in a feedback study)
        self.__dict__[attr] = value
        return value

    def __repr__(self) -> str:
        return f"LazyModule({self._name!r})"
