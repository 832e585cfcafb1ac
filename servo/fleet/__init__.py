"""Fleets: identify, diagnose and simulate many drives at once, on Dask.

One task per recording or drive (batched when tasks are tiny), run by
:mod:`servo.fleet.runner` on a local Dask cluster, an existing one, or in this process;
each command's work is a thin adapter over the single-drive job
(:mod:`servo.fleet.identify`, :mod:`servo.fleet.diagnose`, :mod:`servo.fleet.simulate`)
that turns one drive into one row; :mod:`servo.fleet.job` gathers the rows into the
Parquet table (:mod:`servo.fleet.table`), flags robust outliers
(:mod:`servo.fleet.outliers`), writes ``fleet_report.md`` (:mod:`servo.fleet.report`) and
the population plots (:mod:`servo.fleet.plots`).  :mod:`servo.fleet.synthetic` makes a
fleet of recordings with known defects for tests and demos.  ``docs/fleet.md`` is the
user's guide.
"""
