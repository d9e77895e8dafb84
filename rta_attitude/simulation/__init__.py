"""The sampled-data closed loop (controller -> filter -> zero-order hold -> plant), its record and
metrics: `closed_loop` (compiled step, `simulate`), `trajectory` (the run's record), `metrics`
(violations, summaries)."""
