"""What every stage stands on: errors and bounded checkers, TOML specs, your files and output
folders, provenance and code hashes, zarr stores, the run log, parallel helpers, and the
recording and ground-truth types (``signals``, ``truth``)."""
