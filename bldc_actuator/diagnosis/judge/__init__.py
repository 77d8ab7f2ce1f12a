"""Stage: judge (the simulator as judge). One entry point, :func:`.stage.run`; the simulated verdicts
(:mod:`.simulated`) and the drive's voltage-limit mode (:mod:`.drive_modes`)."""
