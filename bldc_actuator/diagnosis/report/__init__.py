"""Stage: report. One entry point, :func:`.stage.run`; the report document (:mod:`.document`,
``DiagnosisReport``: JSON, markdown, plots), when the data cannot decide (:mod:`.decidability`) and a structured
residual outside the catalogue (:mod:`.residual_structure`)."""
