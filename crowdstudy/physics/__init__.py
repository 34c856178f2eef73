"""Physics-based collision correction of crowd animations (paper Sec. 3.2-3.4).

Every bone of every character is a rigid capsule body; one implicit-Euler step solves
``argmin E_inertia + E_gravity + E_joints + E_collisions + E_control`` with one Newton
iteration and preconditioned CG (Warp kernels, CPU or CUDA). Entry points:

* :func:`correct` (offline, Baseline -> Ours) and :class:`CrowdCorrector` (online);
* :class:`PhysicsConfig` (parameters in sections, the paper's defaults; set by name from
  a TOML file or ``--config KEY=VALUE``, :mod:`crowdstudy.physics.config_file`);
* :class:`ModelBuilder` / :class:`Model`, :class:`State`, :class:`Control`,
  :class:`Solver` (``step(state_in, state_out, control, contacts, dt)``),
  :class:`CollisionPipeline` / :class:`Contacts`;
* :func:`damping_study` (paper Fig. 4).
"""

from crowdstudy.physics.collision import CollisionPipeline, Contacts
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.corrector import CrowdCorrector, correct
from crowdstudy.physics.damping import damping_study
from crowdstudy.physics.model import Model, ModelBuilder
from crowdstudy.physics.solver import Solver
from crowdstudy.physics.state import Control, State

__all__ = [
    "PhysicsConfig",
    "ModelBuilder",
    "Model",
    "State",
    "Control",
    "Solver",
    "CollisionPipeline",
    "Contacts",
    "CrowdCorrector",
    "correct",
    "damping_study",
]
