"""Matplotlib figures of runs, workspaces and designs (matplotlib is imported only here)."""
