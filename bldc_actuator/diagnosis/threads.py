"""OpenBLAS single-threaded around small fits (what threadpoolctl does, without the dependency)."""

from __future__ import annotations


class SingleThreadedBLAS:
    """Run OpenBLAS single-threaded while diagnosing (what threadpoolctl does, without the dependency).

    Every product here is small (tens of columns); on a busy 2-core machine OpenBLAS's thread pool turns a
    30000-element dot product from 10 µs into 8 ms. Restores the previous thread counts on exit; does
    nothing where the library or its symbols are not found."""

    NAMES = (("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
             ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
             ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
             ("openblas_get_num_threads", "openblas_set_num_threads"))

    def __enter__(self):
        self.saved = []
        try:
            import ctypes

            with open("/proc/self/maps") as fh:
                libs = {line.split()[-1] for line in fh if "openblas" in line.lower() and "/" in line}
            for path in libs:
                lib = ctypes.CDLL(path)
                for get, set_ in self.NAMES:
                    if hasattr(lib, get) and hasattr(lib, set_):
                        n = int(getattr(lib, get)())
                        getattr(lib, set_)(1)
                        self.saved.append((getattr(lib, set_), n))
                        break
        except Exception:  # noqa: BLE001 - best effort (no /proc, another BLAS...)
            pass
        return self

    def __exit__(self, *exc):
        for setter, n in self.saved:
            setter(n)
        return False
