"""Stage: search (equation error). One entry point, :func:`.stage.run`."""
