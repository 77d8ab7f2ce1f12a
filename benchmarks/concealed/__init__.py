"""Concealed-effect benchmark for ``bldc-actuator diagnose`` (issue 4, "Proof").

* :mod:`.truth`      — an independent, three-phase-aware truth simulator of a closed-loop robot joint
                       (does NOT import ``bldc_actuator.model`` or ``bldc_actuator.effects``).
* :mod:`.excitation` — joint reference trajectories (gait, sweeps, multisine, fast swings, payload steps).
* :mod:`.cases`      — the cases: which effect is hidden, its true size, the nominal parameter file the
                       user believes, training and held-out recordings; writes CSV + YAML + truth JSON.
* :mod:`.scoring`    — compares a diagnosis JSON report with the truth JSON; tables (text, markdown, JSON).
* :mod:`.thirdparty`, :mod:`.gem_cases` — cases whose truth is a peer simulator (motulator, gym-electric-motor);
                       their recordings are made by :mod:`.thirdparty_sim` / :mod:`.gem_sim` and cached per case
                       by :mod:`.case_kit` (the kit both sets share).

Entry point: ``benchmarks/run_concealed.py``.
"""
