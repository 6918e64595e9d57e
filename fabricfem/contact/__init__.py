"""Contact of the fabric with rigid ellipsoidal body segments [Man2006, ch. 3.3].

Modules: `nodal` (node-to-ellipsoid gaps, lumped nodal areas, penalty / augmented-Lagrangian normal
law, eqs. 3.61, 3.69, Box 3), `friction` (regularised Coulomb friction with return mapping, eqs.
3.46-3.52), `problem` (`ContactProblem`: contact added to a ShellModel's residual and Jacobian for the
implicit solvers), `explicit` (forward-increment Lagrange multipliers, Box 5), `torque` (joint torque of
the contact forces, ch. 5).
"""
from fabricfem.contact.explicit import (
                                        ExplicitContact,
                                        box5_step,
                                        forward_increment_correction,
                                        initial_state,
                                        project_along_gradient,
)
from fabricfem.contact.friction import return_map
from fabricfem.contact.nodal import ContactNodes, contact_nodes, default_penalty
from fabricfem.contact.problem import AugmentationReport, ContactProblem, ContactState
from fabricfem.contact.torque import adjacent_segments, contact_torque

__all__ = ["AugmentationReport", "ContactNodes", "ContactProblem", "ContactState", "ExplicitContact",
           "adjacent_segments", "box5_step", "contact_nodes", "contact_torque", "default_penalty",
           "forward_increment_correction", "initial_state", "project_along_gradient", "return_map"]
