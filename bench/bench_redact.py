"""Time :func:`goniolab.redact.redact` on hostile text of growing size (issue 23.7: the
regex-and-replace version took 5 s on 80 k characters). Linear time shows as a constant
time per megabyte.

    PYTHONPATH=$PWD python bench/bench_redact.py
"""

from __future__ import annotations

import time

from goniolab.redact import redact

CASES = {
    "scheme-like run": lambda n: "a" * (n // 2) + "://" + "b:" * (n // 4),
    "repeated url head": lambda n: "postgresql://u:" * (n // 15),
    "urls without @": lambda n: "x://u:p " * (n // 8),
    "unterminated quote": lambda n: "password='" + "\\'" * (n // 2),
    "real urls": lambda n: "postgresql://u:pw@h/d host=h password=x\n" * (n // 40),
}


def main() -> None:
    for name, make in CASES.items():
        cells = []
        for n in (100_000, 1_000_000, 5_000_000):
            text = make(n)
            t0 = time.perf_counter()
            redact(text)
            dt = time.perf_counter() - t0
            cells.append(f"{len(text) / 1e6:.1f} MB {dt * 1e3:7.1f} ms")
        print(f"{name:20s} " + " | ".join(cells))


if __name__ == "__main__":
    main()
