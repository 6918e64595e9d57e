"""Time integration of the shell [Man2006, sec. 2.3.1.6]: mass, damping, implicit Newmark, generalized-alpha
(PETSc TS ALPHA2), explicit central differences and the critical time step. SI units throughout.

    from fabricfem.dynamics import NewmarkIntegrator, GeneralizedAlphaIntegrator, CentralDifference, critical_time_step
"""
from fabricfem.dynamics.explicit import CentralDifference
from fabricfem.dynamics.mass import InertiaDamping, consistent_mass, lumped_mass, mass_form, material_stiffness_form
from fabricfem.dynamics.newmark import (
                                        DynamicsError,
                                        History,
                                        NewmarkIntegrator,
                                        StepHalving,
                                        TimeIntegrator,
                                        node_monitor,
                                        progress_printer,
)
from fabricfem.dynamics.stability import (
                                        critical_time_step,
                                        discrete_max_frequency,
                                        max_frequency_estimate,
                                        measured_critical_time_step,
                                        plane_stress_wave_speed,
)
from fabricfem.dynamics.ts import GeneralizedAlphaIntegrator, generalized_alpha_parameters

__all__ = ["CentralDifference", "DynamicsError", "GeneralizedAlphaIntegrator", "History", "InertiaDamping",
           "NewmarkIntegrator", "StepHalving", "TimeIntegrator", "consistent_mass", "critical_time_step",
           "discrete_max_frequency", "generalized_alpha_parameters", "lumped_mass", "mass_form",
           "material_stiffness_form", "max_frequency_estimate", "measured_critical_time_step", "node_monitor",
           "plane_stress_wave_speed", "progress_printer"]
