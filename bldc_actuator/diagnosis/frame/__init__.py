"""The model's frame, shared by every stage: the recording as equation error (:mod:`.equation_error`, ``Context``),
the effect library (:mod:`.candidates`), effect selection (:mod:`.selection`), where a residual sits
(:mod:`.locate`), the load behind a compliant transmission (:mod:`.transmission`) and the window replays
(:mod:`.simulate`). Imports no stage."""
