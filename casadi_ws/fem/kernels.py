"""Evaluate a small CasADi function over many elements, fast.

A per-element CasADi ``Function`` (SX, dense inputs and outputs) is evaluated for every element of the mesh.
Two backends give the same numbers:

``c``       CasADi generates C for the element function; a ten-line C loop calls it once per element on
            numpy's memory directly (ctypes, no copies). The shared library is cached on disk under a hash
            of the generated code and of the CPU, so it is compiled once per machine and reused by every
            run and process. It is built for this CPU's instruction set (``-march=native``: the
            corotational stiffness runs ~1.8x faster with its vector instructions; no fused multiply-adds,
            so the numbers do not depend on the CPU), and a cache shared between machines keeps one
            library per kind of CPU.
``casadi``  ``Function.map`` evaluated by CasADi's virtual machine, with numpy <-> DM conversions. No
            compiler needed; ~10x slower on the stiffness, mostly in the conversions.

Only element-sized graphs are ever compiled: compiling a flattened whole-mesh graph exhausts gcc's memory.
The cache directory is ``$CASADI_WS_CACHE`` if set, else ``$XDG_CACHE_HOME/casadi-ws`` or
``~/.cache/casadi-ws``; nothing is written to the working directory.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["ElementBatch", "MAX_COMPILED_CODE", "cache_dir", "have_compiler"]

MAX_COMPILED_CODE = 20_000_000
"""Generated C larger than this (bytes) is not compiled but run on CasADi's virtual machine (slowly): gcc
takes minutes on a single function of 100 MB. No shipped kernel is that large any more (the corotational
10-node Hessian-vector function, once 166 MB, is built per quadrature point: 2.8 MB); the limit is a guard."""

_DRIVER = r"""
#include <stddef.h>
#define {name}_WORKSPACE \
  casadi_int sz_arg, sz_res, sz_iw, sz_w; \
  {name}_work(&sz_arg, &sz_res, &sz_iw, &sz_w); \
  const casadi_real* arg[sz_arg + 1]; \
  casadi_real* res[sz_res + 1]; \
  casadi_int iw[sz_iw + 1]; \
  casadi_real w[sz_w + 1];
int {name}_batch(long m, int nin, const double** in, const long* in_stride,
                 int nout, double** out, const long* out_stride) {{
  {name}_WORKSPACE
  for (long e = 0; e < m; ++e) {{
    for (int i = 0; i < nin; ++i) arg[i] = in[i] + e * in_stride[i];
    for (int j = 0; j < nout; ++j) res[j] = out[j] + e * out_stride[j];
    if ({name}(arg, res, iw, w, 0)) return 1;
  }}
  return 0;
}}
int {name}_scatter(long m, int nin, const double** in, const long* in_stride, long nout, const int* slot,
                   double* data) {{
  {name}_WORKSPACE
  casadi_real out[nout];
  res[0] = out;
  for (long j = 1; j <= sz_res; ++j) res[j] = 0;
  for (long e = 0; e < m; ++e) {{
    for (int i = 0; i < nin; ++i) arg[i] = in[i] + e * in_stride[i];
    if ({name}(arg, res, iw, w, 0)) return 1;
    const int* s = slot + e * nout;
    for (long j = 0; j < nout; ++j) data[s[j]] += out[j];
  }}
  return 0;
}}
"""


def cache_dir() -> Path:
    env = os.environ.get("CASADI_WS_CACHE")
    if env:
        d = Path(env)
    else:
        d = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "casadi-ws"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")


def have_compiler() -> bool:
    return _compiler() is not None


@functools.cache
def _cpu() -> str | None:
    """What ``-march=native`` compiles for: the CPU's model and instruction-set flags; None where they
    cannot be read (then the build is generic, so a shared cache never hands a CPU foreign instructions)."""
    try:
        with open("/proc/cpuinfo") as f:
            lines = [ln for ln in f if ln.startswith(("model name", "flags", "Features", "CPU part"))]
    except OSError:
        return None
    return platform.machine() + "".join(dict.fromkeys(lines)) if lines else None


def _build(fun: ca.Function) -> Path | None:
    cc = _compiler()
    if cc is None:
        return None
    name = fun.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False, "casadi_int": "long long int"})
        cg.add(fun)
        code = Path(cg.generate(tmp + os.sep)).read_text()
    code += _DRIVER.format(name=name)
    key = hashlib.sha256((code + ca.__version__ + (_cpu() or "generic")).encode()).hexdigest()[:16]
    lib = cache_dir() / f"{name}_{key}.so"
    if lib.exists():
        return lib
    if len(code) > MAX_COMPILED_CODE:
        return None
    src = lib.with_suffix(f".{os.getpid()}.c")
    part = lib.with_suffix(f".{os.getpid()}.part")
    try:
        src.write_text(code)
        # gcc's -O2 time grows faster than linearly with one huge straight-line function: the stiffness of
        # a corotational 10-node element (2.5 MB of C) took ~4 min at -O2 and 7 s at -O1
        opt = "-O2" if len(code) < 500_000 else "-O1"
        # -ffp-contract=off: no fused multiply-adds, so a kernel rounds the same on every x86-64 CPU (a task
        # re-run on another machine of a cluster, a checkpoint resumed elsewhere give the same numbers)
        native = [["-march=native", "-ffp-contract=off"]] if _cpu() is not None else []
        for arch in (*native, []):  # a compiler that does not know -march=native: the generic build
            res = subprocess.run([cc, opt, *arch, "-fPIC", "-shared", str(src), "-o", str(part), "-lm"],
                                 capture_output=True, text=True)
            if res.returncode == 0:
                break
        else:
            return None
        os.replace(part, lib)  # atomic: a concurrent process never loads a half-written library
        return lib
    finally:  # also when interrupted: no 100 MB sources left in the cache
        src.unlink(missing_ok=True)
        part.unlink(missing_ok=True)


PARALLEL_OUTPUT = 1_000_000
"""Batches writing at least this many numbers are split over :func:`kernel_threads` threads: the 10-node
trunk's stiffness (4320 elements x 930 numbers: 0.33 s in one thread, 0.15 s in two); below it the
threads' hand-over costs more than they save (a 4-node residual, 0.5 ms, took longer threaded)."""

_POOLS: dict = {}


def kernel_threads() -> int:
    """Threads for a batch: the cores this process may use, or 1 where the process was told to use one
    thread (``OMP_NUM_THREADS=1``: the workers of a pool, each on its own core)."""
    env = os.environ.get("OMP_NUM_THREADS")
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(n, int(env))) if env and env.isdigit() else n


def _pool(threads: int):
    from concurrent.futures import ThreadPoolExecutor

    if threads not in _POOLS:
        _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="casadi-ws-kernel")
    return _POOLS[threads]


class ElementBatch:
    """``fun`` evaluated for every element: inputs (m, n_i) or (n_i,) shared, outputs (m, n_j)."""

    def __init__(self, fun: ca.Function, backend: str = "auto"):
        self.fun = fun
        self.n_in = [fun.numel_in(i) for i in range(fun.n_in())]
        self.n_out = [fun.numel_out(j) for j in range(fun.n_out())]
        for j in range(fun.n_out()):
            if fun.nnz_out(j) != self.n_out[j]:
                raise ValueError(f"{fun.name()}: output {j} must be dense")
        self._lib = None
        if backend in ("auto", "c"):
            path = _build(fun)
            if path is not None:
                self._lib = ctypes.CDLL(str(path))
                self._batch = getattr(self._lib, f"{fun.name()}_batch")
                self._batch.restype = ctypes.c_int
            elif backend == "c":
                raise RuntimeError(f"{fun.name()}: no C compiler found, or its code is larger than "
                                   f"MAX_COMPILED_CODE ({MAX_COMPILED_CODE} bytes), for the 'c' backend")
        self.backend = "c" if self._lib is not None else "casadi"
        self._maps: dict[int, ca.Function] = {}

    def __call__(self, *inputs: np.ndarray) -> list[np.ndarray]:
        m = max(a.shape[0] for a in inputs if np.ndim(a) == 2)
        if self._lib is None:
            return self._call_casadi(m, inputs)
        ins = [np.ascontiguousarray(a, dtype=float) for a in inputs]
        outs = [np.empty((m, n)) for n in self.n_out]
        threads = kernel_threads() if m * sum(self.n_out) >= PARALLEL_OUTPUT else 1
        if threads == 1:
            self._run(ins, outs, 0, m)
        else:  # ctypes releases the GIL: the chunks run on the cores at once
            cuts = [m * k // threads for k in range(threads + 1)]
            list(_pool(threads).map(lambda k: self._run(ins, outs, cuts[k], cuts[k + 1]), range(threads)))
        return outs

    def scatter(self, slot: np.ndarray, size: int, *inputs: np.ndarray) -> np.ndarray:
        """(size,) the sums of the first output's entries by ``slot`` (int32, one per entry, element-major):
        ``np.bincount(slot, out.ravel(), size)`` without the (m, n_out) array.

        Why: a 4-node stiffness batch is 5 MB, written by the kernel and read back by the bincount with its
        slots (1 ms of the linear trunk's 3 ms tangent); summed as each element is computed, only the
        slots are read. The sums are taken in the same order, so the numbers are the bincount's to the bit;
        a batch that runs on threads, or without a compiler, is computed whole and summed by bincount.
        """
        m = max(a.shape[0] for a in inputs if np.ndim(a) == 2)
        n = self.n_out[0]
        if self._lib is None or self.fun.n_out() != 1 or (
                m * n >= PARALLEL_OUTPUT and kernel_threads() > 1):
            out, = self(*inputs)
            return np.bincount(slot, weights=out.ravel(), minlength=size)
        if slot.dtype != np.int32 or slot.size != m * n or not slot.flags.c_contiguous:
            raise ValueError(f"{self.fun.name()}: scatter needs {m * n} contiguous int32 slots")
        if not hasattr(self, "_scatter"):
            self._scatter = getattr(self._lib, f"{self.fun.name()}_scatter")
            self._scatter.restype = ctypes.c_int
        ins = [np.ascontiguousarray(a, dtype=float) for a in inputs]
        data = np.zeros(size)
        in_stride = [a.shape[1] if a.ndim == 2 else 0 for a in ins]
        if self._scatter(ctypes.c_long(m), len(ins), (ctypes.c_void_p * len(ins))(*[a.ctypes.data for a in ins]),
                         (ctypes.c_long * len(ins))(*in_stride), ctypes.c_long(n), ctypes.c_void_p(slot.ctypes.data),
                         ctypes.c_void_p(data.ctypes.data)):
            raise RuntimeError(f"{self.fun.name()}: evaluation failed")
        return data

    def _run(self, ins, outs, start: int, stop: int) -> None:
        """Elements start..stop-1 of the batch into ``outs``."""
        in_stride = [a.shape[1] if a.ndim == 2 else 0 for a in ins]
        in_ptr = (ctypes.c_void_p * len(ins))(*[a.ctypes.data + 8 * int(start) * k for a, k in zip(ins, in_stride)])
        out_ptr = (ctypes.c_void_p * len(outs))(*[a.ctypes.data + 8 * int(start) * n for a, n in zip(outs, self.n_out)])
        if self._batch(ctypes.c_long(stop - start), len(ins), in_ptr, (ctypes.c_long * len(ins))(*in_stride),
                       len(outs), out_ptr, (ctypes.c_long * len(outs))(*self.n_out)):
            raise RuntimeError(f"{self.fun.name()}: evaluation failed")

    def _call_casadi(self, m: int, inputs) -> list[np.ndarray]:
        if m not in self._maps:
            self._maps[m] = self.fun.map(m)
        args = [np.asarray(a, dtype=float).T if np.ndim(a) == 2 else np.asarray(a, dtype=float)[:, None]
                for a in inputs]
        res = self._maps[m](*args)
        res = res if isinstance(res, (list, tuple)) else [res]
        return [np.asarray(r.full()).T.copy() for r in res]
