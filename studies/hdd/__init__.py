"""The NSS HDD benchmark evaluated for a design: ``python -m studies.hdd.evaluate``."""
