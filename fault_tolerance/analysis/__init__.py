"""Analyses over many configurations: the batched API, sweeps, workspaces, designs, inspection."""
