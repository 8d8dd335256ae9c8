"""sdmpi's test suite (a package: its helper modules are imported relative to it)."""
