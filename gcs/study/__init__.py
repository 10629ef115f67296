"""Studies: many fast-mode flights over a grid of parameters (docs/study.md).

* `studyfile`: the study file (YAML) -> a validated, frozen `Study`; its axes expanded into
  `RunSpec`s with stable ids.
* `runs`: one `RunSpec` flown -> one row (a plain function Ray ships to its workers).
* `table`: the append-only JSON-lines table of rows, read back for resume and reports.
* `engines`: where runs execute, in this process or as Ray tasks.
* `report`: per-axis tables (mean, 95 % confidence interval) and figures.
"""
