"""The performance benchmark: what one control step costs, fast path against the slow routes.

For each arm it times, in one process and after a warm-up, single calls of

* ``jacobian``: the task Jacobian (Pinocchio ``computeFrameJacobian``);
* ``lnva``, ``jvja``, ``rcn``, ``mda``: the :class:`~fault_tolerance.control.controller.Controller` steps
  (Jacobian included), with the default backend, and ``lnva_<backend>`` / ``jvja_<backend>`` for
  the other backends installed;
* ``lnva_resolve``, ``jvja_resolve``, ``mda_resolve``, ``rcn_resolve``: ``arm.jacobian`` and the
  plain :func:`fault_tolerance.resolve` / :func:`fault_tolerance.rcn`;
* ``jvja_explicit``: the Jacobian and eq. (5) the explicit way, one pseudo-inverse per scenario for
  eq. (2) (:func:`fault_tolerance.resolution.resolvers.jvja_explicit`);
* ``jvja_qp`` / ``jvja_slsqp``: the Jacobian, eq. (2) per scenario, then the minimisation
  (3)-(4), ``min Σ_S w_S ½‖ˢq̇' - q̇‖²`` s.t. ``J q̇ = ẋ``, handed to a generic solver: the
  dense active-set QP solver ``quadprog`` (if installed) and SciPy's SLSQP (if installed).

Each row is timed call by call in blocks of consecutive calls (a control loop's steady state),
the rows' blocks taking turns over ten rounds so that a drift of the machine hits them alike.
Garbage collection is off while timing (as ``timeit`` does).
Configurations come from a seeded pool of generic postures (no singularity, no near-intolerable
scenario). The table gives the median and the 99th percentile of a call in microseconds, then
the targets with PASS / FAIL. ``--json FILE`` keeps everything (with the machine) for
``--compare A.json B.json``.

Example:
    fault-tolerance bench --robots planar_3r panda_pose --steps 2000 --json new.json

Layout: :mod:`.cases` (arms, pool, the rows of each arm, by group), :mod:`.timing` (how a call is
timed), :mod:`.routes` (the generic-solver routes), :mod:`.targets` (the targets),
:mod:`.report` (tables, JSON, ``--compare``), :mod:`.machine` (the machine), :mod:`.command`
(options and the run).
"""

from __future__ import annotations
