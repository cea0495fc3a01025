"""Explicit MPM with one velocity field per body: multi-velocity frictional contact
(Bardenhagen et al. 2000/2001; seed 004 §2.6.2, eqs 2.34-2.39), penalty node-to-segment
contact (seed 004 eqs 2.40-2.53, contact.penalty) and rigid bodies with
prescribed motion.

Bodies. A particle's body is the optional particle field `body` (int32; set it with
`set_body(particles, body_id, region=None)`, it migrates with the particles under MPI), or,
when the particles have no such field, its `material_id` (so particle sets built with
distinct material objects and added together are distinct bodies). Body ids are 0..nb-1.

Per step (the update orders of fm.Explicit: USF, USL, MUSL, AVG):
  m_i^b = sum_{p in b} N_ip m_p,  (m v)_i^b = sum_{p in b} N_ip m_p v_p,
  grad m_i^b = sum_{p in b} m_p grad N_ip                (mass gradient, for the normals),
  f_i^b = -sum_{p in b} V_p sigma_p . grad N_ip + (m_i^b / m_i) f_ext,i
(all summed over ranks with grid.accumulate, like the single-field arrays), and each body's
trial velocity v_i^b = ((m v)_i^b + dt f_i^b) / m_i^b on its own nodes (m_i^b above the
simulation's mass tolerance times the largest nodal mass).

Contact at a node shared by two or more bodies (seed 004 eqs 2.34-2.39). With the
centre-of-mass velocity v_i^cm = sum_b m_i^b v_i^b / sum_b m_i^b (or, when a rigid body is
present at the node, the rigid body's velocity), for each deformable body A there:
  n^A   the unit outward normal of A from the mass gradients g^b = sum_{p in b} m_p grad N_ip
        (g^b points OUT of body b: it is int rho grad N_i = -int N_i grad rho, and rho
        drops across the surface), made common to the bodies at the node so that n^B = -n^A
        for two bodies (momentum is then conserved exactly):
          normal="max-gradient" (default): the gradient of the body with the largest |g| at
            the node (the master), n^master = g/|g|, n^other = -g/|g|;
          normal="average": n^A = (g^A - g^other)/|...| (Bardenhagen et al. 2001);
          normal={body: vector}: a flat body's prescribed outward normal wherever it is
            present at the node (else max-gradient);
  dv    = v^A - v^cm,  dv_n = dv . n^A,  dv_t = dv - dv_n n^A,
  dv_n <= 0:  separating or sliding apart: no contact force (separation is allowed);
  dv_n > 0 (eq 2.34, approaching): the normal contact force f_norm = -m^A dv_n n^A / dt
              (eq 2.37) removes the normal approach, and the tangential force is the stick
              force f_stick = -m^A dv_t / dt (eq 2.38) capped by Coulomb (eq 2.39):
      |dv_t| <= mu dv_n:  stick,  v^A <- v^cm,
      otherwise:          slip,   v^A <- v^A - dv_n n^A - mu dv_n dv_t / |dv_t|.
Gap check (gap=0.0 by default; gap=None switches it off and gives the plain algorithm of
the seed, which detects contact as soon as two bodies share a node, one cell early). Between
deformable bodies a node takes part only where the bodies' surfaces, estimated from their
particles, meet:
  (x^B - x^A) . n^A - (r^A + r^B) <= gap * h,
with x^b = sum N m_p x_p / m^b the body's mass-weighted particle position at the node,
r^b = sum N m_p (V_p^(1/d) / 2) / m^b its mean particle half-size there, B the master (or
the heaviest other body) and h the cell size (after Nairn's and Lemiale et al.'s
displacement/position-based detection; the seed's eq 2.50 is the corner-based variant).
Without it the front of a rolling cylinder sticks to the plane before it touches it: C1
rolling at h = 0.4 m loses 24 % of its travel (bench `contact`). The estimate puts two flat
bodies touching along a grid line h/4 apart (2 x 2 particles per cell), so against a RIGID
body, whose particles are its surface, the gap is exact instead: along the normal line
through the node, g = min over B's particles of x_p . n - r_p minus max over A's particles
of x_p . n + r_p (particles with N_ip > 0 whose domain reaches that line), and the approach
is limited to dv_n <= max(g - gap h, 0) / dt, so a body resting on a rigid one is in
contact at once and does not sink (issue 17: a block on a rigid 30 deg incline sank 24 mm
and slid 156 mm at mu = 0.7; now 0.03 mm and 0.55 mm).
Friction against a rigid body acts where the interface is: at the nodes on the rigid body's
side of its particle surface along the normal line (x_i . n at or beyond that surface, to
1e-9 h); at a contact node on the deformable body's side only the normal approach is cut.
Such a node's velocity is that of the soil up to a cell below the interface, and sticking it
glued that soil to the body: a rough rigid footing (`problems.footing.strip_footing(h,
mu=10)`) pressed into the cell below its base read 1.349 / 1.158 / 1.072 (2 + pi) c_u at
2 / 5 / 10 cells under B/2, a cell of soil deeper than a smooth one (1.165 / 1.031 / 1.022);
now 1.269 / 1.083 / 1.053. A block on a rigid incline whose face lies on a grid line slides
and sticks to the same bits; the rigid pile of demos/pile_jacking.py (--quick), whose shaft
dragged a cell of sand, met 12.5 kN of resistance instead of 24.4 kN (estimate 7.0 kN; with
Mohr-Coulomb's separation gap, the default then; 16.3 kN without it).
Contact status: the trial projection records per node and body no contact, slip or stick;
MUSL/AVG's re-mapped velocity, which the stress update sees, keeps that decision (normal
relative velocity = the allowed approach, stuck bodies with v^cm) instead of deciding anew,
so the strain sees the bodies in contact exactly where the momentum was. For a flat rigid
body prefer its prescribed normal, normal={body: outward normal}: with the mass-gradient
normal the corners of a sliding block tilt it (-0.96 % on the frictionless incline against
-0.04 %).
For two free bodies the impulses on A and B are equal and opposite (m^A dv^A = -m^B dv^B and
n^B = -n^A), so the step conserves momentum exactly. The contact force on each body is kept per node in
`self.contact_force` (n_nodes, nb, gdim) and its global sum over the step in
`self.body_contact_force` (nb, gdim), e.g. the resistance on a rigid pile.

Rigid bodies: `rigid={body_id: velocity}` with velocity a vector or a function t -> vector.
Their particles move with that velocity (no stress update), their nodal velocity is the
prescribed one, and at a node they share with deformable bodies v^cm is the rigid
velocity (the rigid body has infinite inertia). A rigid body may instead be driven by a
force, rigid={b: fm.RigidLoad(force, gravity)} (contact.rigid: its velocity follows the
applied force, its weight and the contact reaction of the step). `body_contact_force[b]` of a
rigid body is that reaction: minus the contact forces on the other bodies at its nodes.

Penalty contact (algorithm="penalty", 2D; seed 004 eqs 2.40-2.53; contact.penalty
has the equations, the sign convention g_n < 0 = penetration, the Coulomb cap |f_t| <= mu f_n
with f_n >= 0 compressive, the MPI scheme and the stability limit): every body needs a
boundary polyline, `add_polyline(body, vertices, closed=False)`; the vertices move with the
body's grid velocity (with MUSL the re-mapped one, the velocity the stress update sees, so
the springs and the bodies' strain follow one motion), node-to-segment penalty forces
(k_n, k_t, damping: `penalty=dict(k_n=..., k_t=..., damping=...)`, k_t = k_n and damping 0.1
by default) between the bodies' polylines are mapped to each body's nodes as external
forces before the trial velocities, and the nodal projection above is not applied.
Rigid bodies' polylines move with their prescribed velocity. The per-body contact force is
again `body_contact_force`, and `penalty_stats` holds the step's number of pairs, slipping
pairs and largest penetration, and the number of idle vertices (W_v = 0: no mass of their
body around them, so they neither move nor take part).

Paired interface (interface="paired", multi-velocity with a rigid body and the gap check, on
axis-aligned lattices; the default interface="auto" takes it against every rigid body whose
particle domains fill an axis-aligned box, since 2026-12-07, late; measured in
docs/guide/contact.md): at the nodes a
deformable body A shares with a rigid body R whose normal lies within 32 degrees of a grid
axis (PAIR_ALIGNED; 18 degrees before 2026-12-07, evening, when the two nodes of a footing's
edge column left the pairs as their normal turned and the pressure dropped by 7-10 % at 5
cells under B/2), the node below R's surface along that axis and its neighbour above it carry the
surface velocity v_s = xi v_above + (1 - xi) v_below (xi: the surface's height over the lower
node in spacings), and one constraint per pair holds (v_s^A - v_s^R) . n to the allowed
approach, split between the two nodes with the least change of kinetic energy
(paired_rigid_contact). The node-wise projection holds the lower node itself to the body, so
a layer of A up to a cell thick moves with R and the contact force rings with one cell's
period as R's surface crosses node rows (the footing sawtooth of docs/guide/choosing.md).
Since 2026-12-07 each pair's impulse and friction are scaled by R's coverage of the pair's
R-side node where R is an axis-aligned box (the coverage interface below; nodes without a
pair get the node-wise projection scaled the same way), so R no longer acts half a cell
wider when its edge lies on a grid line: Prandtl's footing (bench bearing-capacity's
_row(h, ...), the default) reads 1.0441 / 0.9989 (2 + pi) c_u at 5 / 10 cells under B/2
with its edge on a grid line (coverage: 1.0120 / 1.0265) and 0.9569 / 1.0070 / 0.9962 at
2.5 / 5.5 / 10.5 cells with its edge at a cell centre (coverage 1.1105 / 1.0599 / 1.0321).
The coverage tells faces from corners at 18 degrees (ALIGNED) whatever the pairs' angle:
with 32 degrees there too, the jacked pile's tip corner nodes counted as a face's and its
resistance was 12 % apart between its two finest cells (4 % with 18 degrees there).
Rollers out of the normals (every multi-velocity interface but an explicit "node"): a
Dirichlet-fixed velocity component (a roller: a symmetry plane, the axis of an axisymmetric
grid) is taken out of the mass gradients before the normals are formed, so the contact acts
in the node's free directions: on a half model's symmetry line the mass-gradient normal is
otherwise diagonal and the roller then keeps only half of the normal correction (and the
coverage would count the body's inside as a neighbour along its surface). interface="node"
keeps the diagonal normal (the default before 2026-12-07; its figures are kept as the
bench's -node rows): its half model of Prandtl's footing reads 1.164 / 1.031 (2 + pi) c_u at
2 / 5 cells under B/2, the whole footing 1.374 / 1.116 (problems.footing.strip_footing(
half=False)); the hammered pile of demos/pile_driving.py, whose axis nodes are rollers,
penetrates 0.662 m in its first blow at h = 0.15 m with the diagonal normal and 0.624 m
without it (0.627 / 0.400 m against 0.391 / 0.082 m in the two blows of --quick).

Coverage interface (interface="coverage"; the default interface="auto" took it against
box-shaped rigid bodies until 2026-12-07, late, and takes "node" against the other bodies;
multi-velocity with the gap check on axis-aligned lattices; measured in
docs/guide/contact.md): the node-wise projection against a rigid body R, each correction of
node i (normal and friction) scaled by R's coverage of the node,
    alpha_i = rho_i / max(rho_i, rho_j over i's lattice neighbours j along R's surface),
    rho_i = m^R_i / V_i  (V_i the node's tributary volume: h^d, halved per grid boundary
    crossing it, times r for axisymmetric grids, h_r / 3 on the axis),
so a node that R covers fully (its neighbours along R's surface carry as much of R) is held
as before, and a node at R's edge is held in proportion to the part of its cell patch that R
covers. By the partition of unity, sum_i alpha_i V_i along a row of nodes is about R's own
extent along its surface, so the constrained band of A is as wide as R instead of half a cell
wider: a jacked pile's resistance converges in h, and Prandtl's footing, half model or whole,
comes within 3 % at 10 cells under B/2 (docs/guide/contact.md). The neighbours "along R's
surface" are, where the node's normal lies within 18 degrees of a grid axis (a face), those
along the other axes, and elsewhere (a corner: the pile's tip edge) all lattice neighbours.
On an inclined face a node's neighbour inside R makes alpha_i about 1/2, and at a sharp tip
the half-held nodes let A in (a rigid 30 degree V wedge pushed 0.2 m into a block at h = 0.05
m: the soil 53.9 mm inside it, node-wise 8.4 mm clear; tests/test_coverage_contact.py),
hence "auto"'s boxes (only holding the faces' neighbours at a corner, alpha_i = 1 elsewhere,
left the jacked pile 12 % apart between h = 0.075 and 0.0375 m, against 0.6 % with this rule;
taking as neighbours along R's surface those no deeper in R than the node, or telling corners
from inclined faces by the neighbours' normals, moved the pile's 0.30-0.45 m mean at h =
0.075 m by +22 % / +15 % and failed the rough footing test, 2026-12-07).

Frictional rigid boundaries of the simulation (add_friction) act on every body's field. Robin
boundaries (absorbing dashpots, sim.add_boundary) act on the centre-of-mass nodal velocity
and their force is shared among the bodies at a node by mass, like the external force.
Axisymmetric grids get the hoop terms of fenicsmpm.kernels.axisymmetric per body (both
algorithms; penalty forces per radian, contact.penalty). Particle-layer boundaries are not
supported by this integrator."""
import time

import numpy as np
from numba import njit

from ..kernels import transfer as kt
from ..kernels.transfer import row_length
from ..integrators.explicit import SCHEMES
from ..kernels import axisymmetric as axi
from .penalty import DAMPING as PENALTY_DAMPING, PenaltyContact, check_polyline
from .rigid import RigidLoad

__all__ = ["ExplicitContact", "set_body", "body_ids"]

ALGORITHMS = ("multi-velocity", "penalty")
LATERAL = 1.5           # gap check: particles within LATERAL half-sizes of a node's normal line
NORMALS = ("average", "max-gradient")
INTERFACES = ("auto", "node", "paired", "coverage")
BOX_TOL = 1e-6          # interface "auto": a rigid body's domains fill its bounding box to this
ALIGNED = 0.95          # a face: an axis within 18 deg of the normal (the coverage, _coverage)
PAIR_ALIGNED = 0.85     # interface "paired": within 32 deg (ExplicitContact._pairs)


def set_body(particles, body_id, region=None):
    """Give the particles selected by region(x) (default: all) the body id `body_id` (stored
    in the optional particle field `body`, which migrates with them). Returns the field."""
    if not (isinstance(body_id, (int, np.integer)) and 0 <= body_id < 2 ** 31 - 1):
        raise ValueError(f"set_body: 'body_id' must be an integer >= 0, got {body_id!r}")
    fresh = not hasattr(particles, "body")
    b = particles.add_field("body", (), np.int32)
    if fresh:
        b[:] = particles.material_id
    sel = slice(None) if region is None else np.asarray(region(particles.x))
    if region is not None and sel.shape != (len(particles),):
        raise ValueError(f"set_body: 'region(x)' must return one bool per particle, shape "
                         f"({len(particles)},), got shape {sel.shape}")
    sel = sel if region is None else sel.astype(bool)
    b[sel] = body_id
    return b


def lattice_neighbours(grid):
    """nbr[i, 2 k] / nbr[i, 2 k + 1]: the local node one lattice spacing below / above node i
    along axis k, -1 where none (grid.structured lattices)."""
    st = grid._structured
    ijk = np.rint((grid.node_x - st["origin_global"]) / st["spacing_global"]).astype(np.int64)
    d = grid.gdim
    lo = ijk.min(axis=0) - 1
    ext = ijk.max(axis=0) - lo + 2
    strides = np.cumprod(np.concatenate([[1], ext[:-1]]))
    flat = (ijk - lo) @ strides
    order = np.argsort(flat, kind="stable")
    sflat = flat[order]
    nbr = np.full((len(flat), 2 * d), -1, dtype=np.int64)
    for k in range(d):
        for side, step in ((0, -1), (1, 1)):
            key = flat + step * strides[k]
            pos = np.minimum(np.searchsorted(sflat, key), len(sflat) - 1)
            hit = sflat[pos] == key
            nbr[hit, 2 * k + side] = order[pos[hit]]
    return nbr


def _finite_vector(value):
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return a.ndim == 1 and bool(np.all(np.isfinite(a)))


def body_ids(particles):
    """The body id of every local particle: the `body` field, else material_id."""
    b = getattr(particles, "body", None)
    return np.ascontiguousarray(particles.material_id if b is None else b, dtype=np.int32)


# ---------------------------------------------------------------------------- kernels
@njit(cache=True)
def p2g_bodies(D, nodes, N, dN, body, mass, v, m_b, mv_b, gm_b):
    """m_b[i, b] += N m_p, mv_b[i, b] += N m_p v_p, gm_b[i, b] += m_p grad N (p in body b)."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        mp = mass[p]
        for a in range(row_length(nodes, p)):
            i = nodes[p, a]
            w = N[p, a] * mp
            m_b[i, b] += w
            for k in range(d):
                mv_b[i, b, k] += w * v[p, k]
                gm_b[i, b, k] += mp * dN[p, a, k]


@njit(cache=True)
def p2g_positions_bodies(D, nodes, N, body, mass, x, V, axis_r, xm_b, rm_b):
    """xm_b[i, b] += N m_p x_p and rm_b[i, b] += N m_p V_p^(1/d) / 2 (p in body b): with
    m_b, the body's mass-weighted nodal position and particle half-size (gap check between
    deformable bodies). axis_r: V_p is per radian (axisymmetric grid), the half-size is
    that of the meridian area V_p / r_p (as in surface_extents)."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        vol = V[p] / x[p, 0] if axis_r else V[p]
        r = 0.5 * vol ** (1.0 / d)
        for a in range(row_length(nodes, p)):
            i = nodes[p, a]
            w = N[p, a] * mass[p]
            rm_b[i, b] += w * r
            for k in range(d):
                xm_b[i, b, k] += w * x[p, k]


@njit(cache=True)
def surface_extents(D, nodes, N, body, x, V, axis_r, node_x, ref_n, shared, lo_b, hi_b):
    """Extent of each body along the normal line through every shared node i (direction
    ref_n[i]): lo_b[i, b] = min, hi_b[i, b] = max of x_p . n_i -/+ r_p over the particles p
    of body b with N_ip > 0 whose domain reaches that line (lateral offset <= LATERAL r_p),
    r_p = (V_p)^(1/d) / 2 (meridian size on axisymmetric grids). lo_b starts at +inf, hi_b
    at -inf (gap check of the module docstring)."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        vol = V[p] / x[p, 0] if axis_r else V[p]
        r = 0.5 * vol ** (1.0 / d)
        for a in range(row_length(nodes, p)):
            i = nodes[p, a]
            if N[p, a] <= 0.0 or not shared[i]:
                continue
            s = 0.0
            on = 0.0
            o2 = 0.0
            for k in D:
                s += x[p, k] * ref_n[i, k]
                on += (x[p, k] - node_x[i, k]) * ref_n[i, k]
                o2 += (x[p, k] - node_x[i, k]) ** 2
            if o2 - on * on > (LATERAL * r) ** 2:
                continue
            if s - r < lo_b[i, b]:
                lo_b[i, b] = s - r
            if s + r > hi_b[i, b]:
                hi_b[i, b] = s + r


@njit(cache=True)
def reference_normals(present, rigid, gm_b, mode, n_fixed, has_fixed, ref_n, shared):
    """For every node a rigid body shares with a deformable one: shared[i] = True and
    ref_n[i] the outward normal (_normal) of its first deformable body there; the gap check
    measures the bodies' extents along it."""
    n, nb, d = gm_b.shape
    G = np.empty(d)
    nrm = np.empty(d)
    for i in range(n):
        has_rigid = False
        first = -1
        for b in range(nb):
            if present[i, b]:
                if rigid[b]:
                    has_rigid = True
                elif first < 0:
                    first = b
        if not has_rigid or first < 0:
            continue
        for k in range(d):
            G[k] = 0.0
            for b in range(nb):
                if present[i, b]:
                    G[k] += gm_b[i, b, k]
        if _normal(i, first, present, gm_b, mode, n_fixed, has_fixed, G, nrm):
            shared[i] = True
            for k in range(d):
                ref_n[i, k] = nrm[k]


@njit(cache=True)
def p2g_weighted_bodies(D, nodes, N, body, mass, q, out):
    """out[i, b] += N m_p q_p for p in body b."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        for a in range(row_length(nodes, p)):
            w = N[p, a] * mass[p]
            i = nodes[p, a]
            for k in range(d):
                out[i, b, k] += w * q[p, k]


@njit(cache=True)
def internal_force_bodies(D, nodes, dN, body, V, stress, out):
    """out[i, b] -= V_p sigma_p . grad N_ip for p in body b."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        for a in range(row_length(nodes, p)):
            i = nodes[p, a]
            for k in range(d):
                s = 0.0
                for l in range(d):
                    s += stress[p, k, l] * dN[p, a, l]
                out[i, b, k] -= V[p] * s


@njit(cache=True)
def _normal(i, a, present, gm_b, mode, n_fixed, has_fixed, G, nrm):
    """Unit outward normal of body a at node i into nrm; False when undefined.
    mode 0 "average": n = g^a - g^other; 1 "max-gradient": the mass gradient g of
    the body with the largest |grad m| at the node (the master), outward for a; 2: a body
    with a prescribed outward unit normal n_fixed[b] (has_fixed[b]) present at the node is the
    master (else as mode 1)."""
    nb, d = gm_b.shape[1], gm_b.shape[2]
    if mode == 0:
        for k in range(d):
            nrm[k] = 2.0 * gm_b[i, a, k] - G[k]
    else:
        master = -1
        if mode == 2:
            for b in range(nb):
                if present[i, b] and has_fixed[b]:
                    master = b
                    break
        if master >= 0:
            sgn = 1.0 if master == a else -1.0
            for k in range(d):
                nrm[k] = sgn * n_fixed[master, k]
        else:
            best = -1.0
            for b in range(nb):
                if present[i, b]:
                    g2 = 0.0
                    for k in range(d):
                        g2 += gm_b[i, b, k] * gm_b[i, b, k]
                    if g2 > best:
                        best = g2
                        master = b
            sgn = 1.0 if master == a else -1.0
            for k in range(d):
                nrm[k] = sgn * gm_b[i, master, k]
    nn = 0.0
    for k in range(d):
        nn += nrm[k] * nrm[k]
    if nn <= 0.0:
        return False
    nn = np.sqrt(nn)
    for k in range(d):
        nrm[k] /= nn
    return True


@njit(cache=True)
def multi_velocity_contact(present, m_b, gm_b, rigid, mu, mode, n_fixed, has_fixed, xm_b, rm_b,
                           ref_n, lo_b, hi_b, node_x, surf_tol, gap_tol, dt, v_b, fc, status,
                           hold, cover):
    """The projection of the module docstring, in place on v_b (n_nodes, nb, d); the contact
    force m^A (v_new - v_old) / dt is added to fc. mu: (nb, nb) friction coefficients;
    mode, n_fixed, has_fixed: the normal (see _normal); xm_b, rm_b (p2g_positions_bodies)
    and ref_n, lo_b, hi_b (surface_extents): the gap check between deformable bodies and
    against rigid bodies; gap_tol >= 1e300 switches it off. With the gap check, friction
    against a rigid body acts only at nodes on its side of its surface (node_x . n within
    surf_tol of it or beyond; module docstring). status[i, a]: 0 no
    contact, 1 slip, 2 stick, set by the trial projection (hold=False); with hold=True the
    re-mapped velocity of MUSL/AVG keeps the contact decided in the step: relative normal
    velocity = the allowed approach, stuck bodies move with v^cm; other nodes only get the
    approach cut. cover[i, b]: the factor of every correction of node i against rigid body b
    (1, or the coverage of interface="coverage", ExplicitContact._coverage)."""
    n, nb, d = v_b.shape
    vcm = np.empty(d)
    G = np.empty(d)
    nrm = np.empty(d)
    for i in range(n):
        cnt = 0
        r = -1
        for b in range(nb):
            if present[i, b]:
                cnt += 1
                if rigid[b] and r < 0:
                    r = b
        if cnt < 2:
            continue
        for k in range(d):
            vcm[k] = 0.0
            G[k] = 0.0
        mt = 0.0
        for b in range(nb):
            if present[i, b]:
                for k in range(d):
                    G[k] += gm_b[i, b, k]
                if not rigid[b]:
                    mt += m_b[i, b]
                    for k in range(d):
                        vcm[k] += m_b[i, b] * v_b[i, b, k]
        if r >= 0:
            for k in range(d):
                vcm[k] = v_b[i, r, k]
        elif mt > 0.0:
            for k in range(d):
                vcm[k] /= mt
        else:
            continue
        for a in range(nb):
            if not present[i, a] or rigid[a]:
                continue
            # partner for mu: the heaviest other body at the node (a rigid one first)
            other = r if (r >= 0 and r != a) else -1
            if other < 0:
                mo = -1.0
                for b in range(nb):
                    if b != a and present[i, b] and m_b[i, b] > mo:
                        mo = m_b[i, b]
                        other = b
            if not _normal(i, a, present, gm_b, mode, n_fixed, has_fixed, G, nrm):
                continue
            dvn = 0.0
            for k in range(d):
                dvn += (v_b[i, a, k] - vcm[k]) * nrm[k]
            allowed = 0.0                        # approach allowed until the gap closes
            muab = mu[a, other]
            if gap_tol < 1e300 and rigid[other]:   # exact: the rigid body's particle surface
                s = 0.0
                xs = 0.0
                for k in range(d):
                    s += nrm[k] * ref_n[i, k]
                    xs += node_x[i, k] * ref_n[i, k]
                gap = lo_b[i, other] - hi_b[i, a] if s >= 0.0 else lo_b[i, a] - hi_b[i, other]
                allowed = max(gap - gap_tol, 0.0) / dt
                # on A's side of the rigid surface: no friction (module docstring)
                if (xs < lo_b[i, other] - surf_tol) if s >= 0.0 else (xs > hi_b[i, other] + surf_tol):
                    muab = 0.0
            elif gap_tol < 1e300:                    # deformable bodies still apart: no contact
                gap = -(rm_b[i, a] / m_b[i, a] + rm_b[i, other] / m_b[i, other])
                for k in range(d):
                    gap += (xm_b[i, other, k] / m_b[i, other] - xm_b[i, a, k] / m_b[i, a]) * nrm[k]
                if gap > gap_tol:
                    continue
            al = cover[i, other]
            if hold and status[i, a] > 0:       # in contact: keep it for the whole step
                dvn -= allowed
                for k in range(d):
                    dv = -dvn * nrm[k]
                    if status[i, a] == 2:
                        dv = vcm[k] + allowed * nrm[k] - v_b[i, a, k]
                    dv *= al
                    fc[i, a, k] += m_b[i, a] * dv / dt
                    v_b[i, a, k] += dv
                continue
            if not hold:
                status[i, a] = 0
            if dvn <= allowed:
                continue
            if hold:                            # not in contact: only cut the approach
                for k in range(d):
                    fc[i, a, k] -= al * m_b[i, a] * (dvn - allowed) * nrm[k] / dt
                    v_b[i, a, k] -= al * (dvn - allowed) * nrm[k]
                continue
            dvt2 = 0.0                          # tangential relative velocity
            for k in range(d):
                t = v_b[i, a, k] - vcm[k] - dvn * nrm[k]
                dvt2 += t * t
            dvt = np.sqrt(dvt2)
            imp = dvn - allowed                 # normal impulse per unit mass
            c = 1.0 if dvt <= muab * imp else muab * imp / dvt
            status[i, a] = 2 if c == 1.0 else 1
            for k in range(d):                  # stick (c = 1) or Coulomb slip
                t = v_b[i, a, k] - vcm[k] - dvn * nrm[k]
                dv = al * (-imp * nrm[k] - c * t)
                fc[i, a, k] += m_b[i, a] * dv / dt
                v_b[i, a, k] += dv


@njit(cache=True)
def _pair_apply(i, w, lam, A, n, m_b, v_b, fc, dt, d):
    """v^A_i += lam w / m^A_i n (the pair's normal impulse share), its force into fc."""
    if i < 0 or w == 0.0:
        return
    s = lam * w / m_b[i, A]
    for k in range(d):
        v_b[i, A, k] += s * n[k]
        fc[i, A, k] += m_b[i, A] * s * n[k] / dt


@njit(cache=True)
def paired_rigid_contact(cand, body_a, body_r, present, m_b, gm_b, mu, mode, n_fixed, has_fixed,
                         ref_n, lo_b, hi_b, node_x, nbr, spacing, surf_tol, gap_tol, dt, v_b, fc,
                         status, hold, cover):
    """Contact of a deformable body A with a rigid body R at the nodes cand[i] (one of each
    there, both present, the gap check's normal line through i meeting R), as one constraint
    per pair of nodes across R's surface instead of one per node (interface="paired").

    Along the grid axis k closest to A's outward normal n, the node b on A's side of R's
    surface (at depth xi spacing_k below it along that axis) and its neighbour a on R's side
    carry the velocity at the surface, v_s = xi v_a + (1 - xi) v_b (linear interpolation
    across the cell). Contact holds the normal relative velocity there,
        (v_s^A - v_s^R) . n <= allowed  (the gap check's approach, module docstring),
    with the least change of kinetic energy: dv_j = lam w_j / m^A_j n, w_a = xi, w_b = 1 - xi,
    lam = -(excess) / (w_a^2 / m^A_a + w_b^2 / m^A_b). The node-wise projection holds both
    nodes to the body, so a soil layer xi spacing_k thick moved with a footing and the
    reaction rang with one cell's period as the base crossed node rows. A node without such a
    partner is constrained alone (w = 1). Friction (mu[A, R]) acts at the R-side node as in
    the node-wise projection. Status and hold as in multi_velocity_contact. cover[i, R]: the
    factor of the pair's impulse and friction, taken at its R-side node (the partner, or i
    alone; ExplicitContact._coverage: R's coverage, or 1)."""
    n_nodes, nb, d = v_b.shape
    G = np.empty(d)
    nrm = np.empty(d)
    done = np.zeros(n_nodes, dtype=np.bool_)
    for sweep in range(2):                 # pairs from the A-side nodes first, then singles
        for i in range(n_nodes):
            if not cand[i] or done[i]:
                continue
            A, R = body_a[i], body_r[i]
            for k in range(d):
                G[k] = gm_b[i, A, k] + gm_b[i, R, k]
            if not _normal(i, A, present, gm_b, mode, n_fixed, has_fixed, G, nrm):
                done[i] = True
                continue
            s = 0.0
            zeta = 0.0
            for k in range(d):
                s += nrm[k] * ref_n[i, k]
                zeta += node_x[i, k] * ref_n[i, k]
            if s >= 0.0:
                sigma = lo_b[i, R]
                gap = lo_b[i, R] - hi_b[i, A]
            else:
                sigma = -hi_b[i, R]
                zeta = -zeta
                gap = lo_b[i, A] - hi_b[i, R]
            a_side = zeta < sigma - surf_tol
            if sweep == 0 and not a_side:
                continue
            partner = -1
            xi = 0.0
            if sweep == 0:
                ax = 0
                for k in range(1, d):
                    if abs(ref_n[i, k]) > abs(ref_n[i, ax]):
                        ax = k
                e_ax = ref_n[i, ax] if s >= 0.0 else -ref_n[i, ax]
                j = nbr[i, 2 * ax + (1 if e_ax > 0.0 else 0)]
                if (j >= 0 and cand[j] and not done[j] and body_a[j] == A and body_r[j] == R):
                    partner = j
                    xi = min(max((sigma - zeta) / (abs(e_ax) * spacing[ax]), 0.0), 1.0)
            done[i] = True
            if partner >= 0:
                done[partner] = True
            wa, wb = xi, 1.0 - xi          # a = partner (R side), b = i
            if partner < 0:
                wb = 1.0
                wa = 0.0
            allowed = max(gap - gap_tol, 0.0) / dt
            dvn = 0.0
            for k in range(d):
                rel = wb * (v_b[i, A, k] - v_b[i, R, k])
                if partner >= 0:
                    rel += wa * (v_b[partner, A, k] - v_b[partner, R, k])
                dvn += rel * nrm[k]
            keep = hold and status[i, A] > 0
            if not hold:
                status[i, A] = 0
                if partner >= 0:
                    status[partner, A] = 0
            if not keep and dvn <= allowed:
                continue
            S = wb * wb / m_b[i, A]
            if partner >= 0:
                S += wa * wa / m_b[partner, A]
            lam = -(dvn - allowed) / S
            al = cover[partner if partner >= 0 else i, R]
            lam *= al
            _pair_apply(i, wb, lam, A, nrm, m_b, v_b, fc, dt, d)
            _pair_apply(partner, wa, lam, A, nrm, m_b, v_b, fc, dt, d)
            if hold and not keep:
                continue
            fr = partner if partner >= 0 else (-1 if a_side else i)
            if not hold:
                status[i, A] = 1
                if partner >= 0:
                    status[partner, A] = 1
            if fr >= 0 and mu[A, R] > 0.0:
                imp = abs(lam * (wa if fr == partner else wb) / m_b[fr, A])
                tn = 0.0
                t = np.empty(d)
                dvr = 0.0
                for k in range(d):
                    dvr += (v_b[fr, A, k] - v_b[fr, R, k]) * nrm[k]
                for k in range(d):
                    t[k] = v_b[fr, A, k] - v_b[fr, R, k] - dvr * nrm[k]
                    tn += t[k] * t[k]
                tn = np.sqrt(tn)
                if hold:
                    c = 1.0 if status[fr, A] == 2 else 0.0
                else:
                    c = 1.0 if tn <= mu[A, R] * imp else mu[A, R] * imp / tn
                    status[fr, A] = 2 if c == 1.0 else 1
                for k in range(d):
                    dv = -c * al * t[k]
                    v_b[fr, A, k] += dv
                    fc[fr, A, k] += m_b[fr, A] * dv / dt


@njit(cache=True)
def g2p_bodies(D, nodes, N, body, rigid, v_rigid, dt, v_old, v_new, flip, x, v, u):
    """kernels.transfer.g2p with each particle reading its own body's nodal velocities;
    particles of rigid bodies move with the prescribed velocity v_rigid[b]."""
    d = len(D)
    for p in range(nodes.shape[0]):
        b = body[p]
        if rigid[b]:
            for k in range(d):
                x[p, k] += dt * v_rigid[b, k]
                u[p, k] += dt * v_rigid[b, k]
                v[p, k] = v_rigid[b, k]
            continue
        for k in range(d):
            dx = 0.0
            dv = 0.0
            vp = 0.0
            for a in range(row_length(nodes, p)):
                i = nodes[p, a]
                w = N[p, a]
                dx += w * dt * v_new[i, b, k]
                dv += w * (v_new[i, b, k] - v_old[i, b, k])
                vp += w * v_new[i, b, k]
            x[p, k] += dx
            u[p, k] += dx
            v[p, k] = flip * (v[p, k] + dv) + (1.0 - flip) * vp


@njit(cache=True)
def incremental_F_bodies(D, nodes, dN, body, rigid, w, scale, dF_out):
    """dF_p = I + scale sum_i w[i, body_p] (x) grad N_ip (I for rigid bodies)."""
    d = len(D)
    for p in range(nodes.shape[0]):
        for i in range(3):
            for j in range(3):
                dF_out[p, i, j] = 1.0 if i == j else 0.0
        b = body[p]
        if rigid[b]:
            continue
        for a in range(row_length(nodes, p)):
            n = nodes[p, a]
            for i in range(d):
                wi = scale * w[n, b, i]
                for j in range(d):
                    dF_out[p, i, j] += wi * dN[p, a, j]


# ---------------------------------------------------------------------------- integrator
class ExplicitContact:
    """Explicit MPM (the update orders of fm.Explicit) with one velocity field per body and
    multi-velocity or penalty frictional contact between them (module docstring).

    flip: the FLIP fraction, 1 (pure FLIP) by default for every material; unlike
    fm.Explicit there is no plastic default of 0.99: on Prandtl's smooth footing it measured
    worse (docs/guide/choosing.md, "FLIP fraction for plastic flow").

    mu: Coulomb coefficient between every pair of bodies (>= 0; 0 is frictionless, a large
    value sticks without gluing: separation is still allowed), or a dict {(a, b): mu_ab}
    over body pairs with the default `mu_default` for the others.
    rigid: {body_id: velocity vector or t -> vector} for rigid bodies with prescribed motion,
    or {body_id: fm.RigidLoad(force, gravity)} for a force-driven rigid body.
    normal: "max-gradient", "average" or {body: outward normal}; gap: the gap-check tolerance
    in cell sizes, or None for none (module docstring).
    interface: "auto" (default: "paired" against every rigid body whose particle domains
    fill an axis-aligned box, a footing, pile or wall, on an axis-aligned lattice, and "node"
    elsewhere, with the rollers taken out of the normals; module docstring "Paired
    interface"), "node" (against a rigid body every shared node is projected alone, the
    normals as the mass gradients make them), "paired" (one constraint per pair of nodes
    across a rigid body's surface on axis-aligned lattices, scaled by the coverage against
    box-shaped bodies, paired_rigid_contact; module docstring "Paired interface") or
    "coverage" (the node-wise projection scaled by the rigid body's coverage of each node;
    module docstring "Coverage interface"); multi-velocity only.
    algorithm="penalty": penalty=dict(k_n=..., k_t=..., damping=...) (> 0, >= 0 and >= 0;
    force per unit length per unit penetration/slip, k_t defaults to k_n, about (K + 4G/3)/h
    of the stiffer body; damping the normal dashpot's ratio to critical, default 0.1),
    and a polyline for every body (add_polyline); normal and gap are not used.
    Fields after each step: `body_contact_force` (nb, gdim), the global contact force on each
    body; `nodal` in the simulation holds the centre-of-mass nodal velocity."""
    explicit = True
    records_work = True
    supports_friction = True            # frictional rigid boundaries act on every body's field

    def __init__(self, scheme="MUSL", mu=0.0, algorithm="multi-velocity", flip=1.0,
                 rigid=None, mu_default=0.0, normal="max-gradient", gap=0.0, penalty=None,
                 interface="auto"):
        scheme = str(scheme).upper()
        if interface not in INTERFACES:
            raise ValueError(f"ExplicitContact: 'interface' must be one of {INTERFACES}, got "
                             f"{interface!r}")
        self.interface = interface
        if scheme not in SCHEMES:
            raise ValueError(f"ExplicitContact: 'scheme' must be one of {SCHEMES}, got {scheme!r}")
        if algorithm not in ALGORITHMS:
            raise ValueError(f"ExplicitContact: 'algorithm' must be one of {ALGORITHMS}, got "
                             f"{algorithm!r}")
        if not (0.0 <= flip <= 1.0):
            raise ValueError(f"ExplicitContact: 'flip' must be in [0, 1], got {flip!r}")
        pairs = mu if isinstance(mu, dict) else {}
        vals = list(pairs.values()) + ([] if isinstance(mu, dict) else [mu]) + [mu_default]
        for v in vals:
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"ExplicitContact: 'mu' (friction coefficients, and "
                                 f"'mu_default') must be finite numbers >= 0, got {v!r}")
        self.scheme, self.flip, self.algorithm = scheme, float(flip), algorithm
        self.mu_pairs = {tuple(sorted(k)): float(v) for k, v in pairs.items()}
        self.mu_all = float(mu_default if isinstance(mu, dict) else mu)
        if rigid is not None and not isinstance(rigid, dict):
            raise TypeError(f"ExplicitContact: 'rigid' must be a dict {{body: velocity}}, got "
                            f"{type(rigid).__name__}")
        for b, law in (rigid or {}).items():
            if not (isinstance(b, (int, np.integer)) and b >= 0) or not (
                    callable(law) or _finite_vector(law)):
                raise ValueError(f"ExplicitContact: 'rigid' maps body ids >= 0 to a velocity "
                                 f"vector, t -> vector or fm.RigidLoad, got {b!r}: {law!r}")
        self.rigid = dict(rigid or {})
        if gap is not None and not (isinstance(gap, (int, float, np.floating)) and np.isfinite(gap)):
            raise ValueError(f"ExplicitContact: 'gap' must be None or a finite number, got {gap!r}")
        self.gap = None if gap is None else float(gap)
        self._status = None                  # contact status per node and body (multi-velocity)
        if isinstance(normal, dict):
            self.normal_mode, self.fixed_normals = 2, {int(b): np.asarray(v, dtype=np.float64)
                                                       for b, v in normal.items()}
            for b, v in self.fixed_normals.items():
                if v.ndim != 1 or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
                    raise ValueError(f"ExplicitContact: normal of body {b} must be a non-zero "
                                     f"vector, got {normal[b]!r}")
        elif normal in NORMALS:
            self.normal_mode, self.fixed_normals = NORMALS.index(normal), {}
        else:
            raise ValueError(f"ExplicitContact: 'normal' must be one of {NORMALS} or a dict "
                             f"{{body: outward normal}}, got {normal!r}")
        if (algorithm == "penalty") != (penalty is not None):
            raise ValueError("ExplicitContact: 'penalty' = dict(k_n=..., k_t=...) is required by, "
                             "and only used with, algorithm='penalty'")
        if penalty is not None:
            if (not isinstance(penalty, dict) or "k_n" not in penalty
                    or set(penalty) - {"k_n", "k_t", "damping"}):
                raise ValueError(f"ExplicitContact: 'penalty' must be dict(k_n=..., k_t=..., "
                                 f"damping=...) with k_t and damping optional, got {penalty!r}")
            kn, kt_ = penalty["k_n"], penalty.get("k_t", penalty["k_n"])
            zeta = penalty.get("damping", PENALTY_DAMPING)
            for name, v, lo in (("k_n", kn, 0.0), ("k_t", kt_, None), ("damping", zeta, None)):
                ok = isinstance(v, (int, float, np.floating)) and np.isfinite(v)
                if not ok or (v <= lo if lo is not None else v < 0):
                    raise ValueError(f"ExplicitContact: penalty {name} must be a finite number "
                                     f"{'> 0' if lo is not None else '>= 0'}, got {v!r}")
            self.k_n, self.k_t, self.damping = float(kn), float(kt_), float(zeta)
        self.polylines = []
        self._penalty = None
        self._boxes = None
        self.penalty_stats = None
        self.nb = None
        self.body_contact_force = None

    def add_polyline(self, body, vertices, closed=False):
        """Boundary polyline of body `body` for algorithm="penalty": vertices (n, 2) in order;
        closed=True joins the last to the first (made counter-clockwise); an open one must have
        the body on its left (contact.penalty: circle, rectangle, line)."""
        if self.algorithm != "penalty":
            raise ValueError("ExplicitContact.add_polyline: only for algorithm='penalty'")
        if not (isinstance(body, (int, np.integer)) and body >= 0):
            raise ValueError(f"ExplicitContact.add_polyline: 'body' must be an integer >= 0, "
                             f"got {body!r}")
        self.polylines.append((int(body), check_polyline(vertices, bool(closed)), bool(closed)))
        self._penalty = None

    def setup(self, sim):
        """Check the scene before the first step (integrator protocol: called once)."""
        if sim.layers:
            raise NotImplementedError("ExplicitContact: particle-layer boundaries are not supported")
        if sim.force_integration != "particles":
            raise NotImplementedError("ExplicitContact: force_integration='mixed' is not supported")
        if self.algorithm == "penalty":
            if sim.gdim != 2:
                raise NotImplementedError("ExplicitContact: penalty contact is 2D only")
        self.nb = None
        self._penalty = None
        self._boxes = None

    def checkpoint_state(self):
        """Replicated arrays a checkpoint keeps (fenicsmpm.checkpoint): the velocity of every
        force-driven rigid body (fm.RigidLoad, `rigid_v<body>`) and the penalty polylines'
        vertex positions, last displacements and tangential forces; {} without either."""
        out = {f"rigid_v{b}": np.asarray(law.v, dtype=np.float64)
               for b, law in self.rigid.items() if isinstance(law, RigidLoad) and law.v is not None}
        pc = self._penalty
        if pc is not None:
            out.update(penalty_x=pc.x, penalty_du=pc.du, penalty_ft=pc.ft,
                       penalty_preloaded=np.array([pc._preloaded]))
        return out

    def restore_state(self, state):
        """Take back checkpoint_state: the rigid bodies' velocities now, the penalty state now
        or when the polylines are next built."""
        state = dict(state)
        for key in [k for k in state if k.startswith("rigid_v")]:
            law = self.rigid.get(int(key[len("rigid_v"):]))
            if not isinstance(law, RigidLoad):
                raise ValueError(f"restore: the checkpoint has a force-driven rigid body "
                                 f"{key[len('rigid_v'):]} that this integrator does not "
                                 f"(rigid={{body: fm.RigidLoad(...)}})")
            law.v = np.array(state.pop(key), dtype=np.float64)
        self._restored = state
        if self._penalty is not None:
            self._apply_restored(self._penalty)

    def _apply_restored(self, pc):
        st, self._restored = getattr(self, "_restored", None), None
        if st:
            if st["penalty_x"].shape != pc.x.shape:
                raise ValueError(f"restore: the checkpoint's penalty polylines have "
                                 f"{len(st['penalty_x'])} vertices, this integrator's {len(pc.x)}")
            pc.x, pc.du, pc.ft = (np.array(st[k]) for k in ("penalty_x", "penalty_du", "penalty_ft"))
            pc._preloaded = bool(st["penalty_preloaded"][0])

    def _penalty_state(self, sim):
        """The PenaltyContact of the polylines, built at the first step after a change."""
        if self._penalty is None:
            have = {b for b, _, _ in self.polylines}
            missing = sorted(set(range(self.nb)) - have)
            if missing:
                raise ValueError(f"ExplicitContact(penalty): bodies {missing} have no polyline "
                                 f"(add_polyline)")
            if max(have) >= self.nb:
                raise ValueError(f"ExplicitContact(penalty): polyline of body {max(have)} but the "
                                 f"bodies are 0..{self.nb - 1}")
            self._penalty = PenaltyContact(self.k_n, self.k_t, self.polylines, self.damping)
            self._apply_restored(self._penalty)
        return self._penalty

    # ------------------------------------------------------------------ helpers
    def _bodies(self, sim):
        p = sim.particles
        body = body_ids(p)
        local = int(body.max()) + 1 if len(body) else 0
        if self.nb is None or local > self.nb:
            from mpi4py import MPI
            nb = sim.comm.allreduce(local, op=MPI.MAX) if sim.comm.size > 1 else local
            nb = max(nb, 1 + max(self.rigid, default=-1))
            if body.size and body.min() < 0:
                raise ValueError("ExplicitContact: body ids must be >= 0")
            self.nb = nb
            self._mu = np.full((nb, nb), self.mu_all)
            for (a, b), v in self.mu_pairs.items():
                if a < nb and b < nb:
                    self._mu[a, b] = self._mu[b, a] = v
            self._is_rigid = np.zeros(nb, dtype=np.bool_)
            for b in self.rigid:
                self._is_rigid[b] = True
            loads = [b for b, law in self.rigid.items() if isinstance(law, RigidLoad) and law.mass is None]
            if loads:                            # force-driven rigid bodies: their masses
                mass_b = np.bincount(body, p.mass, minlength=nb)
                if sim.comm.size > 1:
                    mass_b = sim.comm.allreduce(mass_b)
                for b in loads:
                    self.rigid[b].start(mass_b[b], sim.gdim, sim.axisymmetric)
            self._mode = self.normal_mode
            self._n_fixed = np.zeros((nb, sim.gdim))
            self._has_fixed = np.zeros(nb, dtype=np.bool_)
            for b, v in self.fixed_normals.items():
                if v.shape != (sim.gdim,):
                    raise ValueError(f"ExplicitContact: normal of body {b} must have length "
                                     f"{sim.gdim}")
                if b < nb:
                    self._n_fixed[b] = v / np.linalg.norm(v)
                    self._has_fixed[b] = True
        return body

    def _rigid_velocity(self, t, d):
        vr = np.zeros((self.nb, d))
        for b, vel in self.rigid.items():
            vr[b] = np.asarray(vel(t) if callable(vel) else vel, dtype=np.float64)
        return vr

    def _velocities(self, sim, mv_b, inv_mb, free, t):
        """v^b = (m v)^b / m^b on each body's nodes, 0 elsewhere and on fixed components;
        the prescribed velocity for rigid bodies."""
        v = mv_b * inv_mb[:, :, None] * free[:, None, :]
        if self.rigid:
            vr = self._rigid_velocity(t, sim.gdim)
            for b in self.rigid:
                v[:, b, :] = np.where(self._present[:, b, None], vr[b], 0.0)
        return v

    def _contact(self, sim, v_b, dt, fc, trial):
        """Contact between bodies, then frictional boundaries, on the nodal velocities v_b:
        a trial projection decides the contact (trial=True), the re-mapped velocity keeps it;
        then the Dirichlet conditions (sim.fix) again on the deformable bodies, so a contact
        projection never moves a fixed component (a roller on a symmetry line)."""
        if self.nb > 1 and self.algorithm == "multi-velocity":
            if self._status is None or self._status.shape != self._m_b.shape:
                self._status = np.zeros(self._m_b.shape, dtype=np.int8)
            pairs = self._pair_data
            present = self._present if pairs is None else pairs[0]
            multi_velocity_contact(present, self._m_b, self._gm_b, self._is_rigid,
                                   self._mu, self._mode, self._n_fixed, self._has_fixed, self._xm_b,
                                   self._rm_b, self._ref_n, self._lo_b, self._hi_b,
                                   sim.grid.node_x, 1e-9 * sim.grid.h, self._gap, dt,
                                   v_b, fc, self._status, not trial, self._cover)
            if pairs is not None:
                _, cand, body_a, body_r, nbr, spacing = pairs
                paired_rigid_contact(cand, body_a, body_r, self._present, self._m_b, self._gm_b,
                                     self._mu, self._mode, self._n_fixed, self._has_fixed,
                                     self._ref_n, self._lo_b, self._hi_b, sim.grid.node_x, nbr,
                                     spacing, 1e-9 * sim.grid.h, self._gap, dt, v_b, fc,
                                     self._status, not trial, self._cover)
                sim.grid.update_ghosts(v_b.reshape(v_b.shape[0], -1))
        self._friction(sim, v_b, dt, "apply" if trial else "hold")
        if sim.fixed.any():
            free = ~sim.fixed
            for b in range(self.nb):
                if not self._is_rigid[b]:
                    v_b[:, b, :] *= free

    def _interface_bodies(self, sim):
        """The one place the interface is decided: (paired, covered), the rigid bodies whose
        nodes pair across their surface (_pairs) and those whose corrections are scaled by
        their coverage (_coverage):
            "auto"      the box-shaped rigid bodies (_box_bodies), both;
            "paired"    every rigid body paired, the box-shaped ones covered (the pairs'
                        impulses scaled by the coverage of their R-side node);
            "coverage"  none paired, every rigid body covered;
            "node"      none.
        None of either without a rigid body, with the gap check off, with penalty contact or
        on a grid that is not an axis-aligned lattice (the node-wise projection everywhere).
        Collective at the first step (_box_bodies)."""
        if not (self.interface != "node" and self.rigid and self.gap is not None
                and self.algorithm == "multi-velocity" and sim.grid.structured):
            return (), ()
        if self.interface == "coverage":
            return (), tuple(self.rigid)
        boxes = self._box_bodies(sim)
        return (tuple(self.rigid) if self.interface == "paired" else boxes), boxes

    def _box_bodies(self, sim):
        """The rigid bodies whose particle domains fill an axis-aligned box (the domains, boxes
        of the cell's aspect ratio and the particle's volume as shapes.gimp.initial_half_widths
        makes them, summed equal their bounding box to BOX_TOL; on axisymmetric grids in the
        meridian plane); decided at the first step (collective) and kept."""
        if self._boxes is None:
            p, d = sim.particles, sim.gdim
            body = body_ids(p)
            size = p.V / p.x[:, 0] if sim.axisymmetric else p.V
            L = np.asarray(sim.grid._structured["spacing_global"], dtype=np.float64)[:d]
            half = 0.5 * (np.abs(size)[:, None] / np.prod(L)) ** (1.0 / d) * L   # cell's aspect
            ids = sorted(self.rigid)
            lo = np.array([np.min(p.x[body == b, :d] - half[body == b], axis=0, initial=np.inf)
                           for b in ids])
            hi = np.array([np.max(p.x[body == b, :d] + half[body == b], axis=0, initial=-np.inf)
                           for b in ids])
            total = np.array([size[body == b].sum() for b in ids])
            if sim.comm.size > 1:
                from mpi4py import MPI
                for a, op in ((lo, MPI.MIN), (hi, MPI.MAX), (total, MPI.SUM)):
                    sim.comm.Allreduce(MPI.IN_PLACE, a, op=op)
            box = np.where(np.all(hi > lo, axis=1), np.prod(hi - lo, axis=1), 0.0)
            self._boxes = tuple(b for b, v, s in zip(ids, box, total)
                                if v > 0.0 and abs(s - v) <= BOX_TOL * v)
        return self._boxes

    def _lattice(self, grid):
        """(nbr, spacing, V): the grid's lattice neighbours (lattice_neighbours), spacing and
        the nodes' tributary volumes (h^d, halved per boundary of the global grid through the
        node; times r on axisymmetric grids, h_r / 3 on the axis), rebuilt with the grid's
        nodes (collective)."""
        if getattr(self, "_lattice_of", None) is not grid.node_x:     # a rebuilt grid: again
            nbr = lattice_neighbours(grid)
            sp = np.asarray(grid._structured["spacing_global"], dtype=np.float64)
            lo = np.asarray(grid._structured["origin_global"], dtype=np.float64)
            top = np.asarray(grid._structured["upper_global"], dtype=np.float64)
            x = grid.node_x[:, :grid.gdim]
            vol = np.ones(len(nbr))
            for k in range(grid.gdim):        # the global grid's boundary (a ghost node's
                tol = 1e-9 * sp[k]            # neighbours may lie off this rank)
                inner = (x[:, k] > lo[k] + tol) & (x[:, k] < top[k] - tol)
                vol *= np.where(inner, sp[k], 0.5 * sp[k])
            if grid.axisymmetric:
                r = grid.node_x[:, 0]
                vol *= np.where(r > 1e-9 * sp[0], r, sp[0] / 3.0)
            self._lattice_of, self._lattice_data = grid.node_x, (nbr, sp, vol)
        return self._lattice_data

    def _coverage(self, sim):
        """cover[i, b] of multi_velocity_contact: 1, or for the covered rigid bodies
        (_interface_bodies) their coverage alpha_i of node i (module docstring "Coverage
        interface"), computed on the owned nodes and copied to the ghosts."""
        grid = sim.grid
        n, nb = self._m_b.shape
        bodies = self._interface_bodies(sim)[1]
        if not bodies:
            if getattr(self, "_ones", None) is None or self._ones.shape != (n, nb):
                self._ones = np.ones((n, nb))
            return self._ones
        nbr, _, vol = self._lattice(grid)
        cover = np.ones((n, nb))
        along = np.abs(self._ref_n) < ALIGNED        # axes along R's surface at each node
        for b in bodies:
            rho = self._m_b[:, b] / vol
            full = rho.copy()
            for k in range(sim.gdim):
                for side in (0, 1):
                    j = nbr[:, 2 * k + side]
                    ok = along[:, k] & (j >= 0)
                    full[ok] = np.maximum(full[ok], rho[j[ok]])
            cover[:, b] = np.divide(rho, full, out=np.ones(n), where=full > 0.0)
        grid.update_ghosts(cover)
        return cover

    def _pairs(self, sim):
        """The paired interface (paired_rigid_contact) against the paired rigid bodies of
        _interface_bodies, the others node-wise: the nodes it handles, with the presence
        mask the node-wise projection then sees (their rigid body removed), each node's
        deformable and rigid body, the lattice neighbours and spacing; None where no body is
        paired."""
        grid = sim.grid
        paired = self._interface_bodies(sim)[0]
        if not paired:
            return None
        present, rig = self._present, self._is_rigid
        n_def = (present & ~rig).sum(axis=1)
        n_rig = (present & rig).sum(axis=1)
        body_a = np.argmax(present & ~rig, axis=1).astype(np.int32)
        body_r = np.argmax(present & rig, axis=1).astype(np.int32)
        idx = np.arange(len(present))
        boxed = np.zeros(self.nb, dtype=bool)
        boxed[list(paired)] = True
        cand = ((n_def == 1) & (n_rig == 1) & boxed[body_r]
                & np.isfinite(self._lo_b[idx, body_r])
                & np.isfinite(self._hi_b[idx, body_a])
                & (np.abs(self._ref_n).max(axis=1) >= PAIR_ALIGNED))
        masked = present.copy()
        masked[idx[cand], body_r[cand]] = False
        nbr, spacing, _ = self._lattice(grid)
        return masked, cand, body_a, body_r, nbr, spacing

    def _gap_extents(self, sim, body):
        """Data of the gap check (module docstring), summed or maximised over ranks: the
        bodies' mass-weighted positions and particle sizes at every node, and, at nodes
        shared with a rigid body, the bodies' extents along the node's normal; with gap=None
        (or penalty contact) none."""
        grid, nb, p = sim.grid, self.nb, sim.particles
        nn, d = grid.n_nodes, sim.gdim
        none = np.zeros((1, nb))
        self._xm_b, self._rm_b = np.zeros((1, nb, d)), none
        self._ref_n, self._lo_b, self._hi_b, self._gap = np.zeros((1, d)), none, none, 1e308
        if self.gap is None or self.algorithm != "multi-velocity":
            return
        self._gap = self.gap * grid.h
        self._xm_b, self._rm_b = np.zeros((nn, nb, d)), np.zeros((nn, nb))
        p2g_positions_bodies(grid.D, sim.nodes, sim.N, body, p.mass, p.x, p.V, grid.axisymmetric,
                             self._xm_b, self._rm_b)
        self._acc(grid, self._xm_b, self._rm_b)
        if not self.rigid:
            return
        ref_n = np.zeros((nn, d))
        shared = np.zeros(nn, dtype=np.bool_)
        reference_normals(self._present, self._is_rigid, self._gm_b, self._mode, self._n_fixed,
                          self._has_fixed, ref_n, shared)
        lo, hi = np.full((nn, nb), np.inf), np.full((nn, nb), -np.inf)
        surface_extents(grid.D, sim.nodes, sim.N, body, p.x, p.V, grid.axisymmetric, grid.node_x,
                        ref_n, shared, lo, hi)
        if sim.comm.size > 1:
            ext = grid.reduce_max(np.hstack([-lo, hi]))
            lo, hi = -ext[:, :nb], ext[:, nb:]
        self._ref_n, self._lo_b, self._hi_b = ref_n, lo, hi

    def _friction_gaps(self, sim, body):
        """Gaps of every frictional boundary to each deformable body (boundaries.friction);
        collective."""
        self._fgaps = {b: [fr.gaps(sim, np.flatnonzero(body == b)) for fr in sim.frictions]
                       for b in range(self.nb) if not self._is_rigid[b]}

    def _friction(self, sim, v_b, dt, action):
        """Frictional rigid boundaries act on every deformable body's field, with one contact
        status per body and boundary: `apply` to the trial velocities (deciding the contact;
        reaction summed over bodies), `hold` on a velocity the stress update sees."""
        for k, fr in enumerate(sim.frictions):
            for n, (b, gaps) in enumerate(self._fgaps.items()):
                status = fr.body_status.setdefault(b, np.zeros(len(fr.nodes), dtype=np.int8))
                vb = np.ascontiguousarray(v_b[:, b, :])
                if action == "apply":
                    fr.apply(vb, gaps[k], dt, self._m_b[:, b], status, add=n > 0)
                else:
                    fr.hold(vb, gaps[k], dt, status)
                v_b[:, b, :] = vb

    def _stress_update(self, sim, body, v_b, dt):
        dF = sim._dF
        t0 = time.perf_counter()
        incremental_F_bodies(sim.grid.D, sim.nodes, sim.dN, body, self._is_rigid, v_b, dt, dF)
        if sim.axisymmetric:
            axi.hoop_strain(sim.nodes, sim.N, body, self._is_rigid, v_b, dt, sim._r, dF)
        if sim.fbar:
            sim.average_volume_change(dF, body, self.nb)
        sim.timers["constitutive"] += time.perf_counter() - t0
        sim.trial_stress(dF)
        sim.commit(dF)

    @staticmethod
    def _acc(grid, *arrays):
        """grid.accumulate for per-body arrays (n_nodes, nb[, d]) via a 2D view."""
        grid.accumulate(*[a.reshape(a.shape[0], -1) for a in arrays])

    # ------------------------------------------------------------------ step
    def step(self, sim, dt):
        """Advance `sim` by dt (integrator protocol: called by Simulation.step)."""
        if sim.layers:
            raise NotImplementedError("ExplicitContact: particle-layer boundaries are not supported")
        p, grid, T = sim.particles, sim.grid, sim.timers
        D, d = grid.D, sim.gdim
        sim.locate_and_shape()
        p.a[:] = p.v                      # the start-of-step velocity, for the acceleration
        body = self._bodies(sim)                     # after migration
        self._friction_gaps(sim, body)
        nb, nn = self.nb, grid.n_nodes
        t0 = time.perf_counter()
        m_b = np.zeros((nn, nb))
        mv_b = np.zeros((nn, nb, d))
        gm_b = np.zeros((nn, nb, d))
        p2g_bodies(D, sim.nodes, sim.N, sim.dN, body, p.mass, p.v, m_b, mv_b, gm_b)
        self._acc(grid, m_b, mv_b, gm_b)
        m = m_b.sum(axis=1)
        T["p2g"] += time.perf_counter() - t0
        active = sim.active_mask(m)                  # total mass; restricts dN
        mtol = sim.mass_tolerance * (m.max() if len(m) else 0.0)
        if sim.comm.size > 1:
            from mpi4py import MPI
            mtol = sim.comm.allreduce(mtol, op=MPI.MAX)
        present = m_b > mtol
        kt.restrict_gradients(D, sim.nodes, sim.N, sim.dN, present, body)   # per body
        if self.interface != "node" and self.algorithm == "multi-velocity" and sim.fixed.any():
            gm_b = gm_b * (~sim.fixed)[:, None, :]             # no normal across it
        self._present, self._m_b, self._gm_b = present, m_b, gm_b
        self._gap_extents(sim, body)
        self._pair_data = self._pairs(sim)      # the step's pairs, for both projections
        self._cover = self._coverage(sim)
        t0 = time.perf_counter()
        inv_mb = np.divide(1.0, m_b, out=np.zeros_like(m_b), where=present)
        inv_m = np.divide(1.0, m, out=np.zeros_like(m), where=active)
        free = ~sim.fixed
        v0 = self._velocities(sim, mv_b, inv_mb, free, sim.t)
        T["solve"] += time.perf_counter() - t0
        if self.scheme in ("USF", "AVG"):            # the stress sees v0 with the base contact
            v0c = v0
            if sim.frictions:
                v0c = v0.copy()
                self._friction(sim, v0c, dt, "hold")
            self._stress_update(sim, body, v0c, dt if self.scheme == "USF" else 0.5 * dt)
        t0 = time.perf_counter()
        f_b = np.zeros((nn, nb, d))
        stress = sim.dynamic_stress(p.stress)
        internal_force_bodies(D, sim.nodes, sim.dN, body, p.V, stress, f_b)
        if sim.axisymmetric:
            axi.hoop_force(sim.nodes, sim.N, body, p.V, stress, sim._r, f_b)
        self._acc(grid, f_b)
        f_ext = sim.external_force(sim.t, m, active=active)
        share = (m_b * inv_m[:, None])[:, :, None]        # each body's share of a nodal force
        f_b += f_ext[:, None, :] * share
        vcm0 = np.einsum("ib,ibk->ik", m_b, v0) * inv_m[:, None]
        f_robin = sim.boundary_force(vcm0)            # Robin boundaries (summed over ranks)
        if f_robin is not None:
            f_b += f_robin[:, None, :] * share
        t1 = time.perf_counter()
        if self.algorithm == "penalty":
            pc = self._penalty_state(sim)
            fc = pc.forces(sim, present, m_b, self._is_rigid, self._mu, dt)
            f_b += fc
        else:
            fc = np.zeros((nn, nb, d))
        v1 = self._velocities(sim, mv_b + dt * f_b, inv_mb, free, sim.t + dt)
        self._contact(sim, v1, dt, fc, trial=True)
        vcm1 = np.einsum("ib,ibk->ik", m_b, v1) * inv_m[:, None]
        sim.record_work(f_ext, f_robin, vcm0, vcm1, dt)
        t2 = time.perf_counter()
        vr = self._rigid_velocity(sim.t + dt, d) if self.rigid else np.zeros((nb, d))
        if self.algorithm == "penalty" and self.scheme != "MUSL":
            pc.move(sim, present, m_b, v1, self._is_rigid, vr, dt)
        g2p_bodies(D, sim.nodes, sim.N, body, self._is_rigid, vr, dt, v0, v1, self.flip,
                   p.x, p.v, p.u)
        t3 = time.perf_counter()
        T["p2g"] += t1 - t0
        T["solve"] += t2 - t1
        T["g2p"] += t3 - t2
        moved = (body, self._is_rigid, dt * vr, dt * v1)  # what each body's particles moved by
        if self.scheme in ("MUSL", "AVG"):
            mv2 = np.zeros((nn, nb, d))
            p2g_weighted_bodies(D, sim.nodes, sim.N, body, p.mass, p.v, mv2)
            self._acc(grid, mv2)
            v1 = self._velocities(sim, mv2, inv_mb, free, sim.t + dt)
            self._contact(sim, v1, dt, np.zeros_like(fc), trial=False)
            T["p2g"] += time.perf_counter() - t3
            if self.algorithm == "penalty" and self.scheme == "MUSL":   # the velocity the
                pc.move(sim, present, m_b, v1, self._is_rigid, vr, dt)      # stress update sees
        if self.scheme != "USF":
            self._stress_update(sim, body, v1, dt if self.scheme != "AVG" else 0.5 * dt)
        self.contact_force = fc
        if self.algorithm == "penalty":
            self.body_contact_force, self.penalty_stats = pc.body_force, pc.stats
        else:
            own = slice(0, grid.n_owned_nodes)
            tot = fc[own].sum(axis=0)
            added = np.zeros(nb)
            for b in self.rigid:       # reaction of the bodies it pushes at its nodes
                at = present[own, b]
                f_at = fc[own][at]                                   # (nodes, bodies, d)
                tot[b] = -f_at.sum(axis=(0, 1))
                added[b] = float(np.sum(m_b[own][at] * np.any(f_at != 0.0, axis=2)))
            if sim.comm.size > 1:
                tot, added = sim.comm.allreduce(tot), sim.comm.allreduce(added)
            self.body_contact_force = tot
        for b, law in self.rigid.items():
            if isinstance(law, RigidLoad):
                law.advance(sim.t, dt, self.body_contact_force[b],
                            0.0 if self.algorithm == "penalty" else added[b])
        vcm = np.einsum("ib,ibk->ik", m_b, v1) * inv_m[:, None]
        if sim.robin is not None:
            sim.robin_u += dt * vcm
        sim.nodal = dict(mass=m, velocity=vcm, active=active, body_mass=m_b, body_velocity=v1,
                         body_displacement=moved)
        np.subtract(p.v, p.a, out=p.a)    # particle acceleration a = (v_new - v_old) / dt
        p.a /= dt
