"""Coverage that counts what is there (issue 13): a node on a face's edge is a node of that face.

Narrow faces (a 0.3 mm chamfer, a thin ring) get FE nodes on their edges and none inside; a field taken from
a tessellation has no node inside a plane; touching solids share the nodes of their coincident faces.  Each
morphs, and an exactly affine field gives every face within 1e-8 mm of its exact affine image on dense
samples over the face (not only at the nodes).  A face that is truly bare is still refused, and named.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from hot2cold.cli import main
from hot2cold.kernel.sampling import fe_surface_nodes
from hot2cold.core.model import Classification, Role
from hot2cold.kernel.tessellate import tessellate
from hot2cold.pipeline.morph import morph
from hot2cold.testing.synthetic import AffineField

from conftest import face_deviation

FIELD = AffineField.thermal(contraction=-0.004, rotation_deg=0.3, translation=(0.1, -0.2, 0.05))


def _write(path, points):
    np.savetxt(path, np.column_stack([points, FIELD(points)]), delimiter=",", header="x,y,z,dx,dy,dz",
               comments="", fmt="%.17g")
    return path


def _cli(shape, nodes, tmp_path, name, *more) -> int:
    """Exit code of ``hot2cold morph`` on ``shape`` written as STEP and the affine field at ``nodes``."""
    step = tmp_path / f"{name}.step"
    shape.exportStep(str(step))
    field = _write(tmp_path / f"{name}.csv", nodes)
    return main(["morph", str(step), str(field), "-o", str(tmp_path / "cold.step"), *more])


def _chamfered_box():
    import cadquery as cq
    return cq.Workplane().box(60, 60, 10).edges(">Z").chamfer(0.3).val()


def _counterbored_plate():
    """A plate with a counterbore whose floor is a 0.3 mm ring."""
    import cadquery as cq
    return cq.Workplane().box(60, 60, 6).faces(">Z").workplane().cboreHole(30.0, 30.6, 2.0).val()


def _assert_affine(result, tol=1e-8):
    spacing = result.part.diagonal / 200
    worst = [float(d.max()) if len(d) else 0.0 for d in face_deviation(result, FIELD.exact_map, spacing)]
    assert max(worst) <= tol, {k: w for k, w in enumerate(worst) if w > tol}


@pytest.mark.heavy
@pytest.mark.parametrize("make", [_chamfered_box, _counterbored_plate], ids=["chamfer_0.3", "counterbore_ring"])
def test_narrow_faces_with_nodes_on_their_edges_only_morph_exactly(make, tmp_path, capsys):
    """The nodes 1.5 mm apart: the narrow face's area times the node density is 11 to 13 nodes, none inside."""
    shape = make()
    nodes = fe_surface_nodes(shape.wrapped, 1.5, seed=1)[0]
    assert _cli(shape, nodes, tmp_path, "hot", "-q") == 0, capsys.readouterr().err
    result = morph(shape, (nodes, FIELD(nodes)))
    narrow = [k for k in range(len(result.part.faces)) if not np.any(
        (result.classification.role == Role.FACE) & (result.classification.owner == k))]
    assert narrow                                   # the narrow faces have no node inside
    _assert_affine(result)


@pytest.mark.heavy
@pytest.mark.parametrize("which", ["block", "blade"])
def test_tessellation_only_nodes_morph(which, block_shape, blade_shape, tmp_path):
    shape = {"block": block_shape, "blade": blade_shape}[which]
    nodes = np.unique(tessellate(shape).vertices, axis=0)
    result = morph(shape, (nodes, FIELD(nodes)))
    assert all(s.valid and s.closed for s in result.report.solids)
    _assert_affine(result)


def test_a_truly_bare_face_is_still_refused_and_named(tmp_path, capsys):
    shape = _chamfered_box()
    nodes = fe_surface_nodes(shape.wrapped, 1.5, seed=1)[0]
    nodes = nodes[nodes[:, 2] > -4.99]               # the bottom face and its edges lose their nodes
    assert _cli(shape, nodes, tmp_path, "bottom", "-q") == 2
    err = capsys.readouterr().err
    assert re.match(r"hot2cold: error: .*bottom\.csv covers only part of the solid: 1 of its 10 faces gets no FE "
                    r"node within .* mm where .*: face \d+ near \(0, 0, -5\) mm", err), err


@pytest.mark.heavy
def test_touching_solids_share_the_nodes_of_their_coincident_faces(tmp_path, capsys):
    """Two boxes side by side (a compound, as an assembly's STEP holds them): the nodes of the face they
    share lie on a face of each; both solids get them, morph and are valid."""
    import cadquery as cq
    left = cq.Workplane().box(10, 10, 10).val()
    right = cq.Workplane().box(10, 10, 10).translate((10, 0, 0)).val()
    compound = cq.Compound.makeCompound([left, right])
    nodes = fe_surface_nodes(left.wrapped, 1.0, seed=1)[0]
    nodes = np.concatenate([nodes, fe_surface_nodes(right.wrapped, 1.0, seed=2)[0]])
    nodes = np.unique(nodes[np.lexsort(nodes.T)].round(12), axis=0)
    assert _cli(compound, nodes, tmp_path, "two", "-q") == 0, capsys.readouterr().err
    result = morph(compound, (nodes, FIELD(nodes)))
    assert len(result.report.solids) == 2 and all(s.valid and s.closed for s in result.report.solids)
    cls = result.classification
    assert len(cls.node) > len(nodes) and result.report.nodes_total == len(nodes)
    shared = cls.node[len(nodes):]
    assert np.all(np.abs(nodes[shared, 0] - 5.0) < 1e-9)      # the entries added are on the shared plane
    np.testing.assert_array_equal(result.field.points, nodes[cls.node])
    _assert_affine(result)


def test_a_free_face_beside_the_solid_without_nodes_is_named_in_a_warning(tmp_path, capsys):
    """A solid with a loose construction face beside it (as a CATIA STEP may hold) and nodes on the solid
    only: morphed (exit 0), the bare free face named in one warning, not counted among the solid's faces."""
    import cadquery as cq
    box = cq.Workplane().box(10, 10, 10).val()
    loose = cq.Face.makePlane(4, 4, basePnt=(20, 0, 0))
    compound = cq.Compound.makeCompound([box, loose])
    nodes = fe_surface_nodes(box.wrapped, 1.0, seed=1)[0]
    assert _cli(compound, nodes, tmp_path, "loose") == 0
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if line.startswith("WARNING")]
    assert len(warnings) == 1 and "Traceback" not in err, err
    assert re.match(r"WARNING hot2cold\.pipeline\.checks: 1 free face\(s\) beside the solid\(s\), in no solid, get "
                    r"no FE node: face \d+ near \(20, 0, 0\) mm; they are morphed from the field of the faces "
                    r"nearby \(artificial nodes\)$", warnings[0]), warnings[0]


def test_a_vertex_holds_the_nodes_at_the_ends_of_its_other_edges():
    """A face whose edges carry no node is covered when each of its vertices has a node of another edge (or
    of a coincident vertex) at it: the box's top face, with nodes only on its four vertical edges, two of them
    at each top corner, classified to those edges."""
    import cadquery as cq

    from hot2cold.pipeline.checks import face_coverage
    from hot2cold.pipeline.load import load_part
    from hot2cold.settings import Settings

    part = load_part(cq.Workplane().box(10, 10, 10).val(), Settings())
    top = max(part.faces, key=lambda f: f.surface.poles[..., 2].min())
    corners = {v for use in top.uses for v in part.edges[use.edge].vertices}
    upright = [e for e in part.edges if len(set(e.vertices) & corners) == 1]
    assert len(upright) == 4
    role, owner, foot = [], [], []
    for e in upright:
        at = part.vertices[next(iter(set(e.vertices) & corners))]
        for shift in (0.0, -1e-3):                       # on the corner and just below it
            role.append(Role.EDGE)
            owner.append(e.index)
            foot.append(at + [0.0, 0.0, shift])
    n = len(role)
    cls = Classification(np.array(role), np.array(owner), np.full((n, 2), np.nan), np.zeros(n), np.array(foot),
                         np.zeros(n), node_distance=0.01, edge_distance=0.01)
    inner, boundary, covered = face_coverage(part, cls)
    assert inner[top.index] == 0 and boundary[top.index] == 0     # none of its own
    assert covered[top.index]
    far = Classification(cls.role, cls.owner, cls.uv, cls.t, cls.foot - [0.0, 0.0, 1.0], cls.distance,
                         node_distance=0.01, edge_distance=0.01)
    assert not face_coverage(part, far)[2][top.index]           # nodes 1 mm below the corners do not count


def test_a_node_on_a_vertex_or_edge_that_no_face_takes_is_still_the_vertex_or_edge_node():
    """The vise's vertex 335: its node (5e-10 mm off) had foot points classified outside both faces there
    (their pcurves miss the vertex by more than the classifier's tolerance), was ignored, and the faces were
    refused as uncovered.  Here every foot point is classified outside: the nodes on vertices and edges are
    still claimed by them (with foot points on them), the nodes inside the faces are ignored."""
    import cadquery as cq

    from hot2cold.core.domain import Trim
    from hot2cold.io.field import as_field
    from hot2cold.kernel.project import Projector
    from hot2cold.pipeline.classify import classify_nodes
    from hot2cold.pipeline.load import load_part
    from hot2cold.settings import Settings

    class NothingInside(Projector):
        def classify(self, k, uv):
            return np.full(len(np.reshape(uv, (-1, 2))), Trim.OUTSIDE)

    settings = Settings()
    part = load_part(cq.Workplane().box(10, 10, 10).val(), settings)
    corner = part.vertices[:, None, :]
    mid_edge = np.array([[5.0, 5.0, 0.3], [5.0, -2.0, -5.0], [0.0, 5.0, 5.0]])
    inside = np.array([[0.5, 0.5, 5.0], [5.0, 1.0, 2.0]])
    points = np.concatenate([part.vertices + 1e-9, mid_edge, inside])
    field = as_field((points, FIELD(points)), "mm", None)
    cls = classify_nodes(part, field, settings, NothingInside(part.kernel.faces, part.kernel.edges))
    nv = len(part.vertices)
    assert np.all(cls.role[:nv] == Role.VERTEX)
    np.testing.assert_array_equal(cls.owner[:nv], np.argmin(np.linalg.norm(points[:nv] - corner, axis=2), axis=1))
    assert np.all(cls.role[nv:nv + 3] == Role.EDGE)
    np.testing.assert_allclose(cls.foot[nv:nv + 3], mid_edge, atol=1e-9)
    assert np.all(cls.role[nv + 3:] == Role.IGNORED)


def test_node_spacing_is_that_of_the_field_around_a_few_sparse_nodes():
    """A face with nodes only at its corners, 150 mm apart, among nodes 1 mm apart: its spacing is 1 mm (the
    grid points near its nodes are those next to the corners, not the whole face).  Shared foot points count
    once; ignored nodes have none."""
    line = np.column_stack([np.arange(0.0, 151.0), np.zeros(151), np.zeros(151)])       # 1 mm apart
    corners = np.array([[0.0, 0.5, 0.0], [150.0, 0.5, 0.0]])
    foot = np.concatenate([line, line[:1], corners, [[np.nan] * 3]])                     # a shared foot point
    n = len(foot)
    role = np.full(n, Role.FACE)
    role[-1] = Role.IGNORED
    owner = np.zeros(n, int)
    owner[-3:-1] = 1
    cls = Classification(role, owner, np.zeros((n, 2)), np.full(n, np.nan), foot, np.zeros(n),
                         node_distance=0.01, edge_distance=0.01)
    assert np.isnan(cls.spacings[-1]) and cls.spacings[75] == pytest.approx(1.0)
    assert cls.spacings[151] == cls.spacings[0] == pytest.approx(0.5)              # the corner is nearer
    assert cls.spacing(cls.nodes_of(Role.FACE, 1)) == pytest.approx(0.5)
    assert cls.spacing() == pytest.approx(1.0)
    assert cls.spacing(np.array([n - 1])) == float("inf")
