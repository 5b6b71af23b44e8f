"""The arm: Pinocchio models from robot descriptions, tip frames, tasks, catalogs and the arm record of a run."""
