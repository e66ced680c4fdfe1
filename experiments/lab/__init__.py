"""The lab: the measurement scripts docs/benchmarks quotes. Not installed with the wheel; nothing outside the lab imports it."""
