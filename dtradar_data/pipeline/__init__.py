"""Building datasets: the resumable scene -> ray tracing -> Parquet pipeline (:mod:`.builder`: the static and the
moving build over one store step), coverage maps (:mod:`.coverage`) and synthetic tables for tests without a ray
tracer (:mod:`.synthetic`)."""
