"""Evaluate a small CasADi function over many elements, fast.

A per-element CasADi ``Function`` (SX, dense inputs and outputs) is evaluated for every element of the mesh.
Two backends give the same numbers:

``c``       CasADi generates C for the element function; a ten-line C loop calls it once per element on
            numpy's memory directly (ctypes, no copies). The shared library is cached on disk under a hash
            of the generated code and of the CPU, so it is compiled once per machine and reused by every
            run and process. It is built for this CPU's instruction set (``-march=native``: the
            corotational stiffness runs ~1.8x faster with its vector instructions; no fused multiply-adds,
            so the numbers do not depend on the CPU), and a cache shared between machines keeps one
            library per kind of CPU. Where the element function is plain arithmetic (every shipped law),
            the loop runs 4 or 8 elements at a time, one per lane of a vector register
            (``_vector_code``): 2-3x faster, and the same numbers to the bit.
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
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = ["ElementBatch", "MAX_COMPILED_CODE", "MAX_VECTOR_CODE", "cache_dir", "have_compiler"]

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
                   double* data, double* sumsq, const int* gather) {{
  {name}_WORKSPACE
  casadi_real out[nout];
  casadi_real first[in_stride[0] + 1];
  res[0] = out;
  for (long j = 1; j <= sz_res; ++j) res[j] = 0;
  for (long e = 0; e < m; ++e) {{
    for (int i = 0; i < nin; ++i) arg[i] = in[i] + e * in_stride[i];
    if (gather) {{  /* the first input's entries read from a whole vector by index */
      for (long k = 0; k < in_stride[0]; ++k) first[k] = in[0][gather[e * in_stride[0] + k]];
      arg[0] = first;
    }}
    if ({name}(arg, res, iw, w, 0)) return 1;
    const int* s = slot + e * nout;
    for (long j = 0; j < nout; ++j) data[s[j]] += out[j];
    if (sumsq) for (long j = 0; j < nout; ++j) *sumsq += out[j] * out[j];
  }}
  return 0;
}}
"""

MAX_VECTOR_CODE = 1_500_000
"""Generated C larger than this (bytes) keeps the one-element-at-a-time driver: the lanes' build of the
corotational 10-node Hessian-vector function (2.8 MB) took 111 s to compile instead of 6 s."""

_VECTOR = r"""
typedef double {name}_vd __attribute__((vector_size({width})));
#define VD {name}_vd
#define LANES {lanes}
static inline VD {name}_vsq(VD x) {{ return x * x; }}
#define {name}_V1(f) static inline VD {name}_v##f(VD x) \
  {{ VD r; for (int l = 0; l < LANES; ++l) r[l] = f(x[l]); return r; }}
#define {name}_V2(f) static inline VD {name}_v##f(VD x, VD y) \
  {{ VD r; for (int l = 0; l < LANES; ++l) r[l] = f(x[l], y[l]); return r; }}
{wrappers}
static const long {name}_sizes_in[] = {{{n_in}}};
static void {name}_lanes(const VD** arg, VD** res) {{
{body}
}}
/* LANES elements at a time, element e's numbers in lane e % LANES; the last group padded with the last
   element, whose copies are not written back */
#define {name}_GATHER(e0) \
  for (int i = 0, o = 0; i < nin; o += {name}_sizes_in[i++]) \
    for (int l = 0; l < LANES; ++l) {{ \
      const long e = e0 + l < m ? e0 + l : m - 1; \
      if (i == 0 && gather) {{ \
        const int* g = gather + e * {name}_sizes_in[0]; \
        for (long k = 0; k < {name}_sizes_in[0]; ++k) bin[k][l] = in[0][g[k]]; \
        continue; \
      }} \
      const double* p = in[i] + e * in_stride[i]; \
      for (long k = 0; k < {name}_sizes_in[i]; ++k) bin[o + k][l] = p[k]; \
    }}
int {name}_vbatch(long m, int nin, const double** in, const long* in_stride,
                  int nout, double** out, const long* out_stride) {{
  const int* gather = 0;
  VD bin[{total_in}], bout[{total_out}];
  const VD* arg[{n_args}];
  VD* res[{n_res}];
  for (int i = 0, o = 0; i < nin; o += {name}_sizes_in[i++]) arg[i] = bin + o;
  for (int j = 0, o = 0; j < nout; o += out_stride[j++]) res[j] = bout + o;
  for (long e0 = 0; e0 < m; e0 += LANES) {{
    {name}_GATHER(e0)
    {name}_lanes(arg, res);
    for (int j = 0; j < nout; ++j)
      for (int l = 0; l < LANES && e0 + l < m; ++l) {{
        double* p = out[j] + (e0 + l) * out_stride[j];
        for (long k = 0; k < out_stride[j]; ++k) p[k] = res[j][k][l];
      }}
  }}
  return 0;
}}
int {name}_vscatter(long m, int nin, const double** in, const long* in_stride, long nout, const int* slot,
                    double* data, double* sumsq, const int* gather) {{
  VD bin[{total_in}], bout[{total_out}];
  const VD* arg[{n_args}];
  VD* res[{n_res}];
  for (int i = 0, o = 0; i < nin; o += {name}_sizes_in[i++]) arg[i] = bin + o;
  res[0] = bout;
  for (long e0 = 0; e0 < m; e0 += LANES) {{
    {name}_GATHER(e0)
    {name}_lanes(arg, res);
    for (int l = 0; l < LANES && e0 + l < m; ++l) {{  /* element by element, as the scalar driver sums */
      const int* s = slot + (e0 + l) * nout;
      for (long j = 0; j < nout; ++j) data[s[j]] += bout[j][l];
      if (sumsq) for (long j = 0; j < nout; ++j) *sumsq += bout[j][l] * bout[j][l];
    }}
  }}
  return 0;
}}
#undef VD
#undef LANES
"""
_LANE_FUNCTIONS = {"sqrt": 1, "exp": 1, "log": 1, "fabs": 1, "sin": 1, "cos": 1, "tan": 1, "asin": 1, "acos": 1,
                   "atan": 1, "sinh": 1, "cosh": 1, "tanh": 1, "log1p": 1, "expm1": 1, "cbrt": 1, "floor": 1,
                   "ceil": 1, "erf": 1, "pow": 2, "atan2": 2, "fmin": 2, "fmax": 2, "copysign": 2, "fmod": 2}


def _lanes() -> int:
    """Elements per vector: 8 where the CPU has 512-bit registers, else 4 (two 128-bit halves on a CPU
    without AVX, which the compiler splits)."""
    return 8 if " avx512f" in (_cpu() or "") else 4


def _vector_code(code: str, fun: ca.Function) -> str:
    """The element function of CasADi's generated ``code`` rewritten to evaluate several elements at once,
    one per lane of a GCC vector (``{name}_vbatch``, ``{name}_vscatter``), or '' where it uses anything but
    arithmetic and the functions of ``_LANE_FUNCTIONS`` (comparisons, conditionals, calls: the scalar
    driver serves).

    Why: the generated code is one long chain of scalar operations on one element; the compiler finds
    little to vectorise inside it. Across elements every operation is the same, so each lane does one
    element's: the 4-node stiffness kernel ran ~2.5x faster, the 10-node force kernel ~4x. Every lane
    computes what the scalar code computes, operation for operation, with the same rounding (IEEE
    arithmetic and square roots are correctly rounded, no contraction into fused multiply-adds, the other
    functions are libm's, called lane by lane): the numbers are the scalar driver's to the bit.
    """
    name = fun.name()
    match = re.search(r"static int casadi_f0\(const casadi_real\*\* arg, casadi_real\*\* res, casadi_int\* iw, "
                      r"casadi_real\* w, int mem\) \{\n(.*?)\n  return 0;\n\}", code, re.S)
    if match is None:
        return ""
    body = match.group(1)
    body = re.sub(r"arg\[(\d+)\]\? arg\[\1\]\[(\d+)\] : 0", r"arg[\1][\2]", body)
    body = re.sub(r"if \(res\[(\d+)\]!=0\) ", "", body)
    body = re.sub(r"=(-?[0-9][0-9.eE+-]*);", r"=((VD){0} + (\1));", body)  # constants, to every lane
    body = body.replace("casadi_real ", "VD ").replace("casadi_sq(", f"{name}_vsq(")
    used = set(re.findall(r"\b([A-Za-z_]\w*)\(", body)) - {f"{name}_vsq", "VD"}
    if not used <= set(_LANE_FUNCTIONS) or re.search(r"[^\w\s.=+\-*/()\[\];,{}]", body):
        return ""
    for f in used:
        body = re.sub(rf"\b{f}\(", f"{name}_v{f}(", body)
    wrappers = "\n".join(f"{name}_V{_LANE_FUNCTIONS[f]}({f})" for f in sorted(used))
    n_in = [fun.numel_in(i) for i in range(fun.n_in())]
    n_out = [fun.numel_out(j) for j in range(fun.n_out())]
    return _VECTOR.format(name=name, width=8 * _lanes(), lanes=_lanes(), wrappers=wrappers, body=body,
                          n_in=", ".join(map(str, n_in)), total_in=sum(n_in), total_out=sum(n_out),
                          n_args=len(n_in), n_res=len(n_out))


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


def _build(fun: ca.Function, vector: bool = True) -> Path | None:
    """The shared library of ``fun``'s batch drivers: the lanes' (``{name}_vbatch``, ``{name}_vscatter``)
    where ``vector`` and :func:`_vector_code` allow, else the one-element-at-a-time ones (``{name}_batch``,
    ``{name}_scatter``)."""
    cc = _compiler()
    if cc is None:
        return None
    name = fun.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False, "casadi_int": "long long int"})
        cg.add(fun)
        code = Path(cg.generate(tmp + os.sep)).read_text()
    # a lanes' build has no scalar code: compiling both took ~1.5x as long
    lanes = _vector_code(code, fun) if vector and len(code) < MAX_VECTOR_CODE else ""
    code = "#include <math.h>\n" + lanes if lanes else code + _DRIVER.format(name=name)
    key = hashlib.sha256((code + ca.__version__ + (_cpu() or "generic")).encode()).hexdigest()[:16]
    lib = cache_dir() / f"{name}_{key}.so"
    if lib.exists():
        return lib
    if len(code) > MAX_COMPILED_CODE:
        return None
    src = lib.with_suffix(f".{os.getpid()}.c")
    part = lib.with_suffix(f".{os.getpid()}.part")
    try:
        # gcc's -O2 time grows faster than linearly with one huge straight-line function: the stiffness of
        # a corotational 10-node element (2.5 MB of C) took ~4 min at -O2 and 7 s at -O1
        opt = "-O2" if len(code) < 500_000 else "-O1"
        # -ffp-contract=off: no fused multiply-adds, so a kernel rounds the same on every x86-64 CPU (a task
        # re-run on another machine of a cluster, a checkpoint resumed elsewhere give the same numbers)
        native = [["-march=native", "-ffp-contract=off"]] if _cpu() is not None else []
        src.write_text(code)
        for arch in (*native, []):  # a compiler that does not know -march=native: the generic build
            res = subprocess.run([cc, opt, *arch, "-fno-math-errno", "-fPIC", "-shared", str(src), "-o", str(part),
                                  "-lm"], capture_output=True, text=True)
            if res.returncode == 0:
                break
        else:
            # a compiler without GCC's vector extensions: the scalar drivers, kept under this key too, so
            # that the next process does not try the lanes' build again
            scalar = _build(fun, vector=False) if lanes else None
            if scalar is not None:
                shutil.copyfile(scalar, part)
                os.replace(part, lib)
            return scalar
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
    """``fun`` evaluated for every element: inputs (m, n_i) or (n_i,) shared, outputs (m, n_j).

    ``vector=False`` keeps the compiled driver to one element at a time (``lanes == 1``): the reference the
    lanes are tested against.
    """

    def __init__(self, fun: ca.Function, backend: str = "auto", vector: bool = True):
        self.fun = fun
        self.lanes = 1  # elements evaluated at once (see _vector_code)
        self.n_in = [fun.numel_in(i) for i in range(fun.n_in())]
        self.n_out = [fun.numel_out(j) for j in range(fun.n_out())]
        for j in range(fun.n_out()):
            if fun.nnz_out(j) != self.n_out[j]:
                raise ValueError(f"{fun.name()}: output {j} must be dense")
        self._lib = None
        if backend in ("auto", "c"):
            path = _build(fun, vector)
            if path is not None:
                self._lib = ctypes.CDLL(str(path))
                self.lanes = _lanes() if hasattr(self._lib, f"{fun.name()}_vbatch") else 1
                self._batch = getattr(self._lib, f"{fun.name()}_{'v' if self.lanes > 1 else ''}batch")
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

    def scatter(self, slot: np.ndarray, size: int, *inputs: np.ndarray, sumsq: bool = False,
                gather: np.ndarray | None = None):
        """(size,) the sums of the first output's entries by ``slot`` (int32, one per entry, element-major):
        ``np.bincount(slot, out.ravel(), size)`` without the (m, n_out) array. With ``sumsq``, also the sum
        of the squares of the entries (the unassembled forces' norm, which a residual's scale needs). With
        ``gather`` (int32, (m, n_in0)), the first input is a whole vector and element e reads
        ``inputs[0][gather[e]]``: the kernel reads the nodal values where they are, without the (m, n_in0)
        copy numpy's indexing makes (the 4-node trunk's internal forces 231 -> 212 us, one thread).

        Why: a 4-node stiffness batch is 5 MB, written by the kernel and read back by the bincount with its
        slots (1 ms of the linear trunk's 3 ms tangent); summed as each element is computed, only the
        slots are read. The sums are taken in the same order, so the numbers are the bincount's to the bit;
        a batch that runs on threads, or without a compiler, is computed whole and summed by bincount.
        """
        m = len(gather) if gather is not None else max(a.shape[0] for a in inputs if np.ndim(a) == 2)
        n = self.n_out[0]
        direct = self._lib is not None and self.fun.n_out() == 1 and not (
            m * n >= PARALLEL_OUTPUT and kernel_threads() > 1)
        if gather is not None and not (direct and gather.dtype == np.int32 and gather.flags.c_contiguous
                                       and inputs[0].dtype == float and inputs[0].flags.c_contiguous):
            inputs, gather = (np.asarray(inputs[0])[gather], *inputs[1:]), None  # numpy's copy instead
        if not direct:
            out, = self(*inputs)
            data = np.bincount(slot, weights=out.ravel(), minlength=size)
            return (data, float(np.dot(out.ravel(), out.ravel()))) if sumsq else data
        if slot.dtype != np.int32 or slot.size != m * n or not slot.flags.c_contiguous:
            raise ValueError(f"{self.fun.name()}: scatter needs {m * n} contiguous int32 slots")
        if not hasattr(self, "_scatter"):
            self._scatter = getattr(self._lib, f"{self.fun.name()}_{'v' if self.lanes > 1 else ''}scatter")
            self._scatter.restype = ctypes.c_int
        ins = [np.ascontiguousarray(a, dtype=float) for a in inputs]
        data = np.zeros(size)
        ss = ctypes.c_double(0.0)
        in_stride = [a.shape[1] if a.ndim == 2 else 0 for a in ins]
        if gather is not None:
            in_stride[0] = gather.shape[1]
        if self._scatter(ctypes.c_long(m), len(ins), (ctypes.c_void_p * len(ins))(*[a.ctypes.data for a in ins]),
                         (ctypes.c_long * len(ins))(*in_stride), ctypes.c_long(n), ctypes.c_void_p(slot.ctypes.data),
                         ctypes.c_void_p(data.ctypes.data), ctypes.byref(ss) if sumsq else None,
                         None if gather is None else ctypes.c_void_p(gather.ctypes.data)):
            raise RuntimeError(f"{self.fun.name()}: evaluation failed")
        return (data, ss.value) if sumsq else data

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
