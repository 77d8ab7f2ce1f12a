"""The angle-locked torque ripple of two or more torque-sensor logs (e.g. a cogging compensation off and on) at
one order, with uncertainties (:func:`bldc_actuator.diagnosis.torque_balance.ripple_contrast`). The motor current
is left out (the dyno view: torque and motion only).

    python benchmarks/ripple_contrast.py --params ak80_9 off=../shared/data/ak80-9/no_torque_tests/no_comp.csv \\
        on=../shared/data/ak80-9/no_torque_tests/comp.csv [--order 18]
"""

from __future__ import annotations

import argparse
import json

from bldc_actuator.diagnosis import torque_balance as tb
from bldc_actuator.diagnosis.io import loaders
from bldc_actuator.diagnosis.io.cleaning import clean
from bldc_actuator.diagnosis.signals import Signals
from bldc_actuator.params import load_preset


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recordings", nargs="+", metavar="LABEL=FILE")
    ap.add_argument("--params", required=True, metavar="PRESET|PARAMS.yaml")
    ap.add_argument("--order", type=float, default=None, help="compare at this order [per motor revolution]")
    args = ap.parse_args()
    params = load_preset(args.params)
    sigs = {}
    for item in args.recordings:
        label, _, path = item.partition("=")
        if not path:
            raise SystemExit(f"recordings: expected LABEL=FILE, got {item!r}")
        s = clean(loaders.load(path), params=params)
        sigs[label] = Signals(s.time, {k: v for k, v in s.channels.items() if k in ("torque", "velocity", "position")},
                              s.source, meta=s.meta, segments=s.segments)
        r = tb.diagnose(sigs[label], params)
        rip = r.ripple or {}
        print(f"{label}: R2 {r.r2:.3f}; strongest order {rip.get('order', float('nan')):.4g} "
              f"± {rip.get('order_sd', float('nan')):.2g}: {rip.get('amplitude', float('nan')):.3g} "
              f"± {rip.get('amplitude_sd', float('nan')):.2g} N*m, p = {rip.get('p_value', float('nan')):.2g}, "
              f"angle-locked: {rip.get('angle_locked')}")
    c = tb.ripple_contrast(sigs, params, order=args.order)
    print(c.message)
    print(json.dumps(c.to_dict(), default=float))


if __name__ == "__main__":
    main()
