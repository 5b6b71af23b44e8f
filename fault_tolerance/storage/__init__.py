"""Files that are whole or absent: atomic writes, result folders, locks, run files and budgets."""
