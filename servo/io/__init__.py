"""Files: recordings (load, validate, save), run logs (journalled, finalised atomically),
atomic writes, and PNG plots."""
