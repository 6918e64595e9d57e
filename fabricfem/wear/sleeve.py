"""The arm-in-sleeve problem [Man2006, sec. 5.3]: a tube of fabric over a flexing two-ellipsoid arm.

Setup (SI units): the sleeve is an open cylinder of length L [m] and radius R [m] along +x
(`fabricfem.meshes.tube`), its shoulder end (tag end0, x = 0) held (all displacement components zero,
rotations free: "boundary conditions are specified to restrain the motion of fabric nodes around the
shoulder", sec. 5.3), its wrist end free. The arm is `fabricfem.body.default_arm` of
`SleeveConfig.arm` (lengths and girths; default ANSUR II medians, scene keys body.*): upper arm fixed,
forearm flexing about the elbow (+z axis through x = 0.335 m) at constant angular velocity up to
57 degrees. Contact: `fabricfem.contact.ContactProblem` (nodal penalty or augmented Lagrangian,
Coulomb friction with stick points that move with the segments).

Solution routes (SleeveConfig.solver, scene key motion.solver):

* "explicit" (default, as the thesis did, ch. 5): the garment engine (fabricfem.wear.garment.GarmentRun, the
  engine of every wear scene) on the tube and the flexing arm (`build_explicit`; fabricfem.dynamics.CentralDifference, lumped mass eq. 2.82 with the
  rotational masses scaled by `rotary_inertia_scale`, so that the thickness-shear modes do not set the
  step: on mesh I the estimated critical step grows from 4.1e-5 s to 2.0e-4 s at s = 100), mass-proportional
  damping C = alpha M (alpha = `mass_damping` = 10 1/s) for a quasi-static flexion, and the explicit
  forward-increment Lagrange-multiplier contact of [Man2006, Box 5] against the moving arm with Coulomb friction
  (fabricfem.contact.explicit.ExplicitBodyContact; penalty as an option). The torque of a record is the
  contact torque averaged over the record interval (`output_angle_step`). The drag alpha rho t v of the
  damping on the sleeve moving with the forearm (v <= 0.13 m/s at 45 deg/s) is about 2e-3 N m of elbow
  torque: a few per cent of the torque at 57 degrees, but comparable with the torque in the first degrees
  of contact (measured on mesh I at 8 deg: explicit 1.1e-2 N m at 45 deg/s, 5.4e-3 N m at 15 deg/s,
  quasi-static 4.5e-3 N m).
* dynamic similarity (SleeveConfig.dynamic_similarity, scene key motion.dynamic_similarity, explicit route):
  stiff fabrics (II: E = 350 MPa, III: 7.2 GPa) would need c_k / c_I = 17 and 60 times the steps of fabric I
  at the same flexion speed; with similarity the flexion runs at omega c_k / c_ref and the mass damping is
  alpha c_k / c_ref (c = sqrt(E / rho), c_ref of fabric I), which keeps the steps per degree and the
  dimensionless inertia and damping of fabric I and scales the torque with E exactly
  (`SleeveConfig.flexion_speed` derives it).
* "quasistatic" (fabricfem.wear.quasistatic): a sequence of Newton solves at increasing angle alpha_k with the body posed at
  t_k = alpha_k / omega, each starting from the previous equilibrium; the friction history (stick points)
  is committed after each converged step (`ContactProblem.after_converged_step`). A step whose Newton solve
  fails is undone and split in two (down to `min_angle_step`), otherwise `SleeveError` names the angle. It
  stalls where the tube buckles (20.25 deg at mu = 0.1, 17 deg at mu = 0.5 on mesh I) and is kept as the
  static reference of the explicit route at small angles and for the moment-balance test.
* "implicit" (fabricfem.wear.sleeve_implicit): the explicit route's equations (lumped mass, mass damping, gravity,
  rest, flexion) by backward Euler, steps of angle_step / omega solved by Newton with the augmented Lagrangian
  (Uzawa updates, eq. 3.69) or penalty; the inertia and damping regularise the buckling steps (it reaches 57 deg).

Newton at one angle (the plain solve stalled at 20.2 deg, mu = 0.1, and 12.6 deg, mu = 0.5, on
mesh I) uses two devices, neither of which changes the converged solution:
* the active-set strategy of ContactProblem (`active_set`, default on): contact set and slip set are fixed
  during one Newton solve and updated from the converged state until they no longer change, which removes the
  leave / re-enter cycling of the non-smooth contact law (the contact asks the arm's skin, fabricfem.body.skin);
* a damped Newton step (`StepLimiter`): the linearised step of the nearly free director rotations is
  radians long from an out-of-balance start and the iterates ran away (residual 1e1 -> 1e10 N) even on a
  fixed contact set; each update is scaled so that no director angle changes by more than
  `max_rotation_step` and no displacement by more than `max_displacement_step` per iteration.
The viscous drag of `Stabilized` remains the fallback of a failed solve.

Gravity: on by default on the explicit route, g = 9.81 m/s^2 along -y, opposite to the flexion (the
forearm "rotates upward"), and the arm first rests for `settle_time` = 0.4 s while the sleeve settles on it
under its weight (rho t g = 4.3 Pa for fabric I, 0.81 N for the whole sleeve). Reasons: (1) the thesis's
sleeve has weight: at mu = 0.1 it "slips down as the forearm rotates upward", at mu = 0.5 friction "prevents
the sleeve from falling down onto the elbow joint" (sec. 5.3.1-5.3.2), which only a weight along -y does;
(2) without it the sleeve floats concentric around the arm (4.3 mm clearance, no contact before 5 degrees)
and the only forces that press it on the forearm are its inertia and the mass-damping drag, so the torque
depends on the flexion rate (mesh I, mu = 0.5, mean over 1-57 deg: 40 % higher at 45 than at 15 deg/s; the
non-monotonic, noisy curves of the first study), whereas with the weight it changes by 6.4 % between 45
and 15 deg/s (tests/test_explicit_sleeve.py checks 45 vs 22.5 deg/s against the drag + inertia bound).
The rest lets the sleeve's fall (about 12 mm onto the forearm; damping time 1 / alpha = 0.1 s) die out
before the flexion: the start record is the torque at rest (the weight the forearm carries, 0.023 N m on
mesh I). The quasi-static route keeps gravity off by default (its start-pose solve of the floating sleeve
under its weight did not finish within 600 s on mesh I; not investigated further).

Elbow torque ([Man2006, ch. 5] intro): the moment about the elbow of all contact forces (normal + friction)
that the sleeve exerts on the forearm,

    tau = a . sum_{i on forearm} (x_i - J_elbow) x f_i          (fabricfem.body.motion.joint_torque)

and the resisting torque reported is -tau [N m], positive when the sleeve opposes flexion.
"""
from __future__ import annotations

import math

from mpi4py import MPI

from fabricfem.body.arm import ArmDimensions, default_arm, elbow_flexion
from fabricfem.body.blended import BLEND_WIDTH
from fabricfem.body.pose import Body
from fabricfem.body.skin import Skin
from fabricfem.dynamics.stability import plane_stress_wave_speed, step_safety
from fabricfem.materials import Fabric
from fabricfem.meshes import tube
from fabricfem.shell import ShellModel
from fabricfem.wear.config import ContactSpec, FlexionSpec, RouteSpec, SleeveConfig, TubeSpec
from fabricfem.wear.garment import ExplicitSettings, GarmentRun, Timeline, TorqueSpec, build_garment_run

GRAVITY = 9.81                       # m/s^2
ELBOW_AXIS = (0.0, 0.0, 1.0)          # flexion axis of the default arm
# the sleeve's torque monitors: the thesis's resisting torque (forces on the forearm) and both segments' forces
ARM_MONITORS = (TorqueSpec("elbow", "elbow", ELBOW_AXIS, ("forearm",)),
                TorqueSpec("elbow_both_segments", "elbow", ELBOW_AXIS, ("upper_arm", "forearm")))


def track_elbow_torques(contact, body: Body) -> None:
    """Register the sleeve's torque monitors (ARM_MONITORS) with a contact (the Newton routes' ContactProblem)."""
    body.check_segments([s for spec in ARM_MONITORS for s in spec.segments])
    for spec in ARM_MONITORS:
        contact.track_torque(spec.name, spec.joint, spec.axis, list(spec.segments))


def sleeve_shell(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> ShellModel:
    """The sleeve's tube shell: shoulder end (end0) held, optional gravity along -y."""
    # second-order geometry: the Q2 mid-side nodes lie on the circle (on a first-order mesh they sit on the
    # chords, at R cos(pi / n_around): 1.4 mm closer to the arm on mesh I, a third of the 4.3 mm clearance)
    t = config.tube
    fmesh = tube(t.length, t.radius, t.n_around, t.n_along, cell="quadrilateral", order=2,
                 comm=comm)
    # no director re-basing: re-basing moves the discrete equilibrium by O(h^2) between steps (measured on
    # mesh I: a residual of 10% of the contact forces after every step); the rotations stay far from the
    # two-angle singularity (|theta1| = pi/2) during a 57-degree flexion
    model = ShellModel(fmesh, config.fabric, rebase=False, psri_degrees=config.tube.quadrature)
    model.constrain("end0", u=(0.0, 0.0, 0.0), theta=(0.0, 0.0) if config.tube.hold_rotations else None)
    if config.route.gravity:
        model.add_gravity((0.0, -GRAVITY, 0.0))
    return model




def similarity_factor(fabric: Fabric, route: RouteSpec) -> float:
    """c / c_ref of dynamic similarity (SleeveConfig.flexion_speed), 1 without it."""
    if not route.dynamic_similarity:
        return 1.0
    E_ref, rho_ref = route.similarity_reference
    return plane_stress_wave_speed(fabric) / math.sqrt(E_ref / rho_ref)


def flexion_timeline(motion: FlexionSpec, route: RouteSpec, similarity: float, arm: ArmDimensions,
                     sewing_time: float = 0.0) -> tuple[Body, Timeline, tuple]:
    """The arm flexing at `motion.angular_velocity` x `similarity` [deg/s] after `motion.settle_time` / similarity
    of rest (with gravity), its timeline (a record every `output_angle_step` degrees) and the elbow-angle axis."""
    omega = math.radians(motion.angular_velocity * similarity)
    flexion = elbow_flexion(arm, angular_velocity=omega, final_angle=math.radians(motion.final_angle))
    timeline = Timeline(record_time=math.radians(motion.output_angle_step) / omega, sewing_time=sewing_time,
                        settle_time=motion.settle_time / similarity if route.gravity else 0.0,
                        motion_time=math.radians(motion.final_angle) / omega)
    axis = ("elbow angle [deg]", lambda t: min(math.degrees(flexion.angle(t)), motion.final_angle))
    return default_arm(flexion, arm), timeline, axis


def flexion_settings(route: RouteSpec, similarity: float) -> ExplicitSettings:
    """The engine's settings of the arm's flexion: mass damping alpha x similarity [1/s], gravity along -y (the
    forearm rotates up, towards +y), the critical step by the largest eigenvalue unless `route` says otherwise."""
    critical_step = route.critical_step or "eigenvalue"
    return ExplicitSettings(mass_damping=route.mass_damping * similarity,
                            stiffness_damping=route.stiffness_damping / similarity,
                            damping_frame=route.damping_frame,
                            rotary_inertia_scale=route.rotary_inertia_scale,
                            time_step_safety=step_safety(route.time_step_safety, critical_step),
                            critical_step=critical_step, mass_scale=route.mass_scale,
                            gravity=(0.0, -GRAVITY, 0.0) if route.gravity else None)


def tube_flexion_run(name: str, fabric: Fabric, tube_spec: TubeSpec, arm: ArmDimensions, motion: FlexionSpec,
                     contact: ContactSpec, route: RouteSpec, comm: MPI.Comm = MPI.COMM_WORLD,
                     config: object = None, skin: Skin | None = None,
                     blend_width: float = BLEND_WIDTH) -> GarmentRun:
    """The arm in a tube sleeve on the garment engine: the tube's shoulder end (end0) held, the arm flexing at the
    elbow (`flexion_timeline`), the torque monitors ARM_MONITORS; `skin`: another skin of the arm (e.g. a rigged
    mesh, fabricfem.body.mesh_skin) instead of the blended ellipsoids of `blend_width` [m]. `fabricfem run` of a tube-on-arm scene and the
    sleeve study's explicit route (`build_explicit`) both build their run here."""
    similarity = similarity_factor(fabric, route)
    body, timeline, axis = flexion_timeline(motion, route, similarity, arm)
    # second-order geometry: the Q2 mid-side nodes lie on the circle (on a first-order mesh they sit on the
    # chords, 1.4 mm closer to the arm on mesh I, a third of the 4.3 mm clearance)
    fmesh = tube(tube_spec.length, tube_spec.radius, tube_spec.n_around, tube_spec.n_along, cell="quadrilateral",
                 order=2, comm=comm)
    return build_garment_run(name, fmesh, fabric, body, holds=["end0"],
                             clamped=["end0"] if tube_spec.hold_rotations else [], torques=ARM_MONITORS,
                             timeline=timeline, settings=flexion_settings(route, similarity),
                             contact_method=contact.method or "lagrange", friction=contact.friction,
                             penalty=contact.penalty, psri_degrees=tube_spec.quadrature, config=config, axis=axis,
                             self_contact=contact.self_contact, self_contact_distance=contact.self_contact_distance,
                             self_friction=contact.self_friction,
                             self_contact_passes=contact.self_contact_passes,
                             impact_zones=contact.impact_zones, skin=skin, blend_width=blend_width)


def build_explicit(config: SleeveConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> GarmentRun:
    """The explicit route of a sleeve configuration: `tube_flexion_run` of its parts."""
    if config.fabric.density <= 0.0:
        raise ValueError("density: the explicit sleeve needs a positive fabric density [kg/m^3]")
    return tube_flexion_run(config.name, config.fabric, config.tube, config.arm, config.motion, config.contact,
                            config.route, comm, config)
