"""Stage: fit (output-error refit, the parameter file). One entry point, :func:`.stage.run`; the joint
output-error refit (:mod:`.output_error`) and the base-model check (:mod:`.base_model`)."""
