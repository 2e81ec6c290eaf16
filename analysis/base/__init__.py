"""The shared base both halves import: the registry of plug-ins by name (``registry``), atomic
file writes and JSON (``files``), and where independent pieces of work run: this process, local
processes or a Dask cluster (``executors``). It imports nothing of the project beyond itself."""
