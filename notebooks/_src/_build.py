"""Shared tail of the notebook generators: execute the cells in a fresh kernel (from
`notebooks/`, so data paths are `../../shared/data`) and write the notebook with its
outputs."""

import nbformat as nbf
from nbclient import NotebookClient


def build(cells: list, name: str, *, timeout: int = 900) -> None:
    """Execute `cells` and write them to `notebooks/<name>`."""
    nb = nbf.v4.new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    NotebookClient(
        nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": "notebooks"}}
    ).execute()
    nbf.write(nb, f"notebooks/{name}")
    print(f"written notebooks/{name}")
