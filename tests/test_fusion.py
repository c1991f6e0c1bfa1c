"""Tests for shadeform.fuse: several views' reconstructions -> one closed mesh.

Scored against the closed synthetic objects' true surfaces (``shadeform.synth``): Chamfer
distance and F-score (``shadeform.metrics``), volume error, watertightness (trimesh). Views are
rendered by ``synth.render_views``; reconstructions are either the single-photo solver's own
(``shadeform.reconstruct`` on the rendered photo) or the true depth with an unknown offset per
view, which isolates the fusion from the single-photo errors.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import shadeform
from helpers.fusion import SMALL, fused_truth, photographed, scores, true_views
from shadeform import synth
from shadeform.errors import InputError
from shadeform.fusion import place
from shadeform.fusion.geometry import axis_column, turntable
from shadeform.fusion.register import _Fit
from shadeform.reconstruction import Reconstruction

SIZE = 256  # the bars are set at 256x256 views


# tests that place the same views share them (helpers.fusion caches them per worker)
WAISTED = pytest.mark.xdist_group("waisted-256")
PEBBLE = pytest.mark.xdist_group("pebble-256")


@pytest.mark.parametrize("name", ["ellipsoid", pytest.param("pebble", marks=PEBBLE), "lumpy"])
def test_true_depths_fuse_to_the_object(name):
    angles = (0, 90, 180, 270)
    mesh, (chamfer, fscore, volume, closed) = fused_truth(name, angles, size=SIZE)
    assert closed
    assert chamfer <= 0.5 and fscore >= 95 and volume <= 3, (chamfer, fscore, volume)
    # outward normals: they point away from the object's centre
    outward = np.sum(mesh.normals * (mesh.vertices - mesh.vertices.mean(axis=0)), axis=1)
    assert np.mean(outward > 0) > 0.99


def test_photos_of_a_lumpy_sphere_from_four_sides():
    """The issue's bar, end to end: 4 photos at 256, each solved alone, then fused."""
    angles = (0, 90, 180, 270)
    views = synth.render_views("lumpy", angles, size=256)
    recs = [shadeform.reconstruct(view.image, mask=view.mask, light=(0, 0, 1)) for view in views]
    mesh = shadeform.fuse(list(zip(recs, angles)))
    chamfer, fscore, volume, closed = scores(mesh, "lumpy", size=256)
    assert closed and chamfer <= 0.5 and fscore >= 95 and volume <= 3, (chamfer, fscore, volume)


@WAISTED
def test_the_other_views_settle_a_waist_one_photo_reads_as_a_hill_top():
    """The waisted object's front and back photos each read the waist as a third hill top and
    one lobe 25 px too deep (Chamfer over 2 %; a quarter of the volume gone while the offsets
    were the gaps' low percentile, 5 % since they are taken on the contour generators); with ``resolve``
    the side views' silhouettes settle the waist as concave and the model meets the bars of the
    shapes without a concavity, stricter than the waisted one's 2 %. The lobe the outline does
    not settle either stays convex."""
    from shadeform.fusion import place, solid

    angles = (0, 90, 180, 270)
    views, recs, solve_again = photographed("waisted", angles, size=SIZE)
    asked = []

    def resolve(i, regions):
        asked.append(i)
        return solve_again(i, regions)

    guessed = scores(shadeform.fuse(list(zip(recs, angles))), "waisted", size=SIZE)
    assert guessed[0] > 2, guessed
    placement = place(list(zip(recs, angles)), resolve=resolve)
    chamfer, fscore, volume, closed = scores(solid(placement), "waisted", size=SIZE)
    assert closed and chamfer <= 0.5 and fscore >= 95 and volume <= 3, (chamfer, fscore, volume)
    # only the photos with unsure areas were solved again, and only the waist (at the middle
    # column) is read as concave
    assert set(asked) == {0, 2}
    assert [len(marked) for marked in placement.concave] == [1, 0, 1, 0]
    for marked in (placement.concave[0], placement.concave[2]):
        assert abs(marked[0]["centre"][0] - (SIZE - 1) / 2) < 0.05 * SIZE
    # the readings placed are the settled ones: their depth is the true one up to an offset
    for rec, view in zip(placement.readings, views):
        error = rec.depth[view.mask] - view.depth[view.mask]
        assert np.std(error) < 0.5
    assert placement.rivals == ()  # from the exact poses nothing else explains the photos


@WAISTED
def test_a_placement_the_photos_do_not_decide_names_its_rival():
    """Four views 90 degrees apart, the side views given 8.9 and 9.5 degrees off: the front and
    back photos read with the waist as a hill explain the photos with the object turned by 16.5
    degrees about as well as the truth (``benchmarks/results/fusion-draws.md``). Whichever is
    kept, the other is named as its rival: the side views turned by the 16.5 degrees."""
    from shadeform.fusion import CLEARLY

    angles = (0, 90, 180, 270)
    _, recs, resolve = photographed("waisted", angles, size=SIZE)
    given = np.add(angles, [0.0, 8.86, 0.23, 9.52])
    placement = place(list(zip(recs, given)), resolve=resolve)
    (rival,) = placement.rivals
    assert 1 / CLEARLY <= rival.ratio <= CLEARLY
    assert rival.turns[0] == rival.turns[2] == 0.0
    assert abs(rival.turns[1] - 16.5) < 1 and abs(rival.turns[3] - 16.5) < 1


@PEBBLE
def test_poses_off_by_up_to_ten_degrees_are_refined():
    angles = (0, 90, 180, 270)
    recs = true_views("pebble", angles, size=SIZE)
    rng = np.random.default_rng(3)
    wrong = [0.0, *(a + rng.choice([-1, 1]) * rng.uniform(6, 10) for a in angles[1:])]
    _, exact = fused_truth("pebble", angles, size=SIZE)
    refined = scores(shadeform.fuse(list(zip(recs, wrong)), refine_poses=True), "pebble", size=SIZE)
    unrefined = scores(shadeform.fuse(list(zip(recs, wrong)), refine_poses=False), "pebble", size=SIZE)
    assert refined[3] and refined[0] <= 0.5 and refined[1] >= 95 and refined[2] <= 3, refined
    assert refined[0] <= exact[0] + 0.05
    assert unrefined[0] > 2 * refined[0]  # the refinement did the work


def test_poses_of_a_waisted_body_are_refined_to_the_exact_ones():
    # 8 views of a body whose lobes hide each other: its far lobe's points lie behind the near
    # lobe in the neighbouring views, across a depth edge, where a Jacobian taken by moving the
    # points over that edge jumped; the poses stopped 4-8 degrees off
    angles = tuple(range(0, 360, 45))
    recs = true_views("waisted", angles)
    rng = np.random.default_rng(5)
    wrong = [0.0, *(a + rng.choice([-1, 1]) * rng.uniform(6, 10) for a in angles[1:])]
    placement = place(list(zip(recs, wrong)))
    turns = np.degrees([np.arctan2(view.rotation[0, 2], view.rotation[0, 0]) for view in placement.views])
    # the issue's claim: as accurate as from the exact poses (the diagonal views' far lobe, behind
    # an occluding contour, is not trusted: from exact poses too they end 0.17 degrees off)
    exact = place(list(zip(recs, angles)))
    settled = np.degrees([np.arctan2(view.rotation[0, 2], view.rotation[0, 0]) for view in exact.views])
    assert np.abs((turns - settled + 180) % 360 - 180).max() < 0.05  # 180 and -180 are one turn
    assert np.abs((turns - angles + 180) % 360 - 180).max() < 0.35


def test_the_surface_behind_a_views_own_occluding_contour_is_not_trusted():
    # seen from 45 degrees the waisted body's far lobe shows beside the near one, beyond the near
    # lobe's rim; one photo cannot say how far behind it lies (the solver integrates across the
    # rim), so the view's depth is trusted on the near lobe's piece only
    from shadeform.fusion.volume import RIM_NZ, trusted_surface

    (view,) = synth.render_views("waisted", (45,), size=SMALL)
    mask, normals = np.asarray(view.mask), np.asarray(view.normals)
    trusted = trusted_surface(mask, normals)
    facing = mask & (normals[..., 2] > RIM_NZ)
    hidden = facing & ~trusted
    assert hidden.sum() > 0.2 * facing.sum() and (trusted & facing).sum() > 0.5 * facing.sum()
    # the hidden pixels lie behind the trusted ones' rim: deeper than every trusted facing pixel
    # next to them, and all on one lobe (the far one)
    assert np.median(view.depth[hidden]) < np.median(view.depth[trusted & facing]) - 0.1 * SMALL
    near = ndimage.binary_dilation(hidden, iterations=3) & trusted & facing
    assert view.depth[hidden].max() < np.median(view.depth[near])
    rows, cols = np.nonzero(hidden)
    left = cols < np.nonzero(trusted & facing)[1].mean()
    assert left.all() or (~left).all()
    # a view in one piece (the front view's two lobes and waist face it) is trusted everywhere
    (front,) = synth.render_views("waisted", (0,), size=SMALL)
    assert (
        trusted_surface(np.asarray(front.mask), np.asarray(front.normals)) == np.asarray(front.mask)
    ).all()


def test_placements_are_compared_on_every_piece_of_the_views():
    # the refinement leaves out what lies beyond a view's own occluding contour (its depth may be
    # off), but where that depth is right it tells a turned view from the true pose: the far
    # lobe of the waisted body seen from 45 degrees; compared with it, the turn costs more
    from shadeform.fusion.register import _samples, disagreement

    angles = tuple(range(0, 360, 45))
    truth = place(list(zip(true_views("waisted", angles), angles)), refine_poses=False)
    views = list(truth.views)
    hidden = views[1].mask & ~views[1].trusted
    every = _samples(views[1], every_piece=True)
    assert hidden[every[:, 0], every[:, 1]].any() and not hidden[tuple(_samples(views[1]).T)].any()
    turned = list(views)
    turned[1] = views[1].at(turntable(4.0)[:3, :3] @ views[1].rotation, views[1].translation, views[1].offset)
    ratios = []
    for every_piece in (False, True):
        right, scale = disagreement(views, turntable=True, every_piece=every_piece)
        wrong, _ = disagreement(turned, turntable=True, scale=scale, every_piece=every_piece)
        ratios.append(wrong / right)
    assert ratios[1] > 1.1 * ratios[0] and ratios[0] > 1, ratios


@WAISTED
def test_a_reading_chosen_at_poses_far_off_is_tried_again_from_the_given_ones(monkeypatch):
    # at these poses (each off by 6-10 degrees) the hull picked the back view's reading that
    # turns its surface (one lobe deeper), and the refinement turned that view 16.7 degrees off
    # to match it; tried again from the given poses, the right reading agrees several times
    # better and every pose comes out exact
    angles = tuple(range(0, 360, 45))
    views, recs, resolve = photographed("waisted", angles, size=SIZE)

    import shadeform.fusion as fusion

    samples = []
    refine = fusion.refine_poses
    monkeypatch.setattr(
        fusion, "refine_poses", lambda views, **kw: samples.append(kw.get("samples")) or refine(views, **kw)
    )
    wrong = np.add(angles, [0.0, 9.2, 8.1, 6.2, -7.5, 6.2, -6.2, -8.6])
    placement = place(list(zip(recs, wrong)), resolve=resolve)
    # the trials (refinements with fewer points) are bounded by the views' number
    assert 0 < samples.count(fusion.TRIAL_SAMPLES) <= fusion.TRIALS_PER_VIEW * len(angles)
    turns = np.degrees([np.arctan2(view.rotation[0, 2], view.rotation[0, 0]) for view in placement.views])
    assert np.abs((turns - angles + 180) % 360 - 180).max() < 0.35
    for i in (0, 4):  # the front and back views: their waist read as concave
        view = views[i]
        error = placement.readings[i].depth[view.mask] - view.depth[view.mask]
        assert np.std(error) < 0.5


def test_a_pose_given_at_the_promised_ten_degrees_may_be_refined_past_them():
    # a pose given 9.95 degrees off (within the promise) whose truth the trial refinement finds
    # 0.08 degrees further on lies 10.03 degrees from it: the bound on corrections must not
    # reject it (8 waisted views, a seeded draw: that view's right placement agreed 13 times
    # better and was dropped); a placement turned by the two lobes' 16.5 degrees still is
    from shadeform.fusion import CORRECTED, _beyond

    angles = tuple(range(0, 360, 45))
    truth = place(list(zip(true_views("waisted", angles), angles)), refine_poses=False)
    views, spacing = list(truth.views), truth.grid.spacing
    given = [turntable(a) for a in angles]
    given[4] = turntable(angles[4] + 9.95)

    def turned(by):
        moved = list(views)
        rotation = turntable(by)[:3, :3] @ views[4].rotation
        moved[4] = views[4].at(rotation, views[4].translation, views[4].offset)
        return moved

    assert not _beyond(turned(0.0), given, spacing, turntable=True)
    assert not _beyond(turned(-0.08), given, spacing, turntable=True)
    assert _beyond(turned(-16.5), given, spacing, turntable=True)
    # past the bound by a turn that moves the view's silhouette edge by two voxels: too far
    mask = views[4].mask
    edge = np.abs(np.nonzero(mask)[1] - views[4].column0).max()
    past = CORRECTED - 9.95 + np.degrees(2 * spacing / edge)
    assert views[4].trusted[mask].all() and _beyond(turned(-past), given, spacing, turntable=True)


def test_disagreement_leaves_out_what_another_view_cannot_see():
    # seen from the side views, the waisted body's far lobe lies behind the near one: those
    # points have nothing to disagree with, and counted they would add the loss's ceiling
    from shadeform.fusion.register import TUKEY, disagreement

    angles = (0, 90, 180, 270)
    recs = true_views("waisted", angles)
    placement = place(list(zip(recs, angles)), refine_poses=False)
    views = list(placement.views)
    loss, scale = disagreement(views, turntable=True)
    fit = _Fit(views, True)
    r = fit.residuals(views)
    hidden = fit.depth_rows() & (r < -TUKEY * scale)
    assert hidden.sum() > 0.01 * len(r)  # the far lobe: tens of pixels behind the near one
    assert not (fit.depth_rows() & (r > TUKEY * scale)).any()  # nothing stands in front
    counted = np.minimum(np.abs(r[~hidden]) / (TUKEY * scale), 1)
    expected = np.sum((TUKEY * scale) ** 2 / 6 * (1 - (1 - counted**2) ** 3)) / (~hidden).sum()
    assert loss == pytest.approx(expected)
    # a view turned by 5 degrees disagrees several times more (4.4 times; 8.0 while the offsets
    # were the gaps' low percentile, which on exact depths sits a little closer)
    turned = list(views)
    rotation = turntable(5.0)[:3, :3] @ turned[1].rotation
    turned[1] = turned[1].at(rotation, turned[1].translation, turned[1].offset)
    assert disagreement(turned, turntable=True, scale=scale)[0] > 4 * loss


@pytest.mark.parametrize("on_turntable", [True, False])
def test_the_refinement_jacobian_is_the_residuals_derivative(on_turntable):
    """A kernel against its reference (a private name, deliberately): the refinement's
    (``register._Fit``) analytic Jacobian is the residuals' finite differences, on and off the
    turntable."""
    angles = (0, 80, 185, 265)
    recs = true_views("ellipsoid", angles, size=96)
    # off the pixel grid, so that no point sits on a kink of the bilinear lookups
    poses = (
        angles if on_turntable else [_shifted(turntable(a), [0.3, 0.13 * a / 90 - 0.2, 0.1]) for a in angles]
    )
    views = list(place(list(zip(recs, poses)), refine_poses=False).views)
    fit = _Fit(views, on_turntable)
    r, jacobian = fit.residuals(views, jacobian=True)
    # per block (pair of views): the silhouette distances, then the tangent-plane gaps
    silhouette = np.concatenate(
        [
            np.arange(2 * len(s)) < len(s)
            for u, s in enumerate(fit.samples)
            for v in range(len(views))
            if v != u
        ]
    )
    for k in range(jacobian.shape[1]):
        delta = 1e-6
        step = np.zeros(jacobian.shape[1])
        step[k] = delta
        moved = fit.residuals(fit.moved(views, step))
        change = (moved - r) / delta
        kept = (moved != 0) == (r != 0)  # a point that crossed a silhouette changes its kind
        sil, gap = kept & silhouette, kept & ~silhouette
        assert np.allclose(change[sil], jacobian[sil, k], atol=1e-3)
        # the gaps' derivative holds the other view's tangent plane fixed (ICP's linearisation):
        # the true depths' normals are that plane up to the bilinear lookups (measured: 4-25 %
        # apart; a wrong sign or frame is 100-200 % apart)
        error = np.linalg.norm(change[gap] - jacobian[gap, k]) / np.linalg.norm(jacobian[gap, k])
        assert error < 0.35, (k, error)


def _shifted(pose, translation):
    pose = pose.copy()
    pose[:3, 3] = translation
    return pose


def test_matrices_give_what_their_angles_give():
    angles = (0, 120, 240)
    recs = true_views("ellipsoid", angles)
    by_angle = shadeform.fuse(list(zip(recs, angles)), refine_poses=False)
    by_matrix = shadeform.fuse(list(zip(recs, [turntable(a) for a in angles])), refine_poses=False)
    volumes = [trimesh.Trimesh(m.vertices, m.faces).volume for m in (by_angle, by_matrix)]
    assert abs(volumes[0] / volumes[1] - 1) < 0.005
    assert abs(len(by_angle.faces) - len(by_matrix.faces)) < 0.01 * len(by_angle.faces)


def test_the_axis_column_is_found_from_opposite_silhouettes():
    # the object (so the turntable's axis) 9.5 px right of the image centre
    shift = np.eye(4)
    shift[0, 3] = 9.5
    poses = [shift @ turntable(a) for a in (0, 90, 180, 270)]
    views = synth.render_views("lumpy", poses=poses, size=SMALL)
    column = axis_column([v.mask for v in views], [0, 90, 180, 270])
    assert abs(column - ((SMALL - 1) / 2 + 9.5)) < 0.3
    recs = true_views("lumpy", None, poses=poses)  # angles None: the poses say it
    mesh = shadeform.fuse(list(zip(recs, (0, 90, 180, 270))))
    chamfer, fscore, volume, closed = scores(mesh, "lumpy")
    assert closed and chamfer <= 0.5 and volume <= 3, (chamfer, volume)


def test_bad_views_get_one_line():
    recs = true_views("ellipsoid", (0, 90))
    cases = [
        ([(recs[0], 0)], "at least two views"),
        ([recs[0], recs[1]], "(reconstruction, pose) pairs"),
        ([(recs[0], 0), (true_views("ellipsoid", (90,), size=96)[0], 90)], "96x96"),
        ([(recs[0], 0), (recs[1], np.eye(3))], "view 2: a pose must be a finite 4x4 matrix"),
        ([(recs[0], 0), (recs[1], 2 * np.eye(4))], "rotation"),
        ([(recs[0], 0), (recs[1], float("nan"))], "finite"),
    ]
    empty = Reconstruction(
        normals=recs[1].normals, depth=recs[1].depth, mask=np.zeros_like(recs[1].mask),
        light=recs[1].light, albedo=1.0,
    )  # fmt: skip
    cases.append(([(recs[0], 0), (empty, 90)], "empty mask"))
    far = np.eye(4)
    far[0, 3] = (
        500.0  # the same direction, the object 500 px to the side: the silhouettes' cylinders never meet
    )
    cases.append(([(recs[0], 0), (recs[1], far)], "share no volume"))
    for views, words in cases:
        with pytest.raises(InputError) as caught:
            shadeform.fuse(views)
        message = str(caught.value)
        assert words in message and "\n" not in message, message


def test_cli_fuses_photos_with_angles_or_a_views_file(tmp_path):
    import json

    from PIL import Image
    from typer.testing import CliRunner

    from shadeform.cli import app

    angles = (0, 90, 180, 270)
    names = []
    for view in synth.render_views("pebble", angles, size=SMALL):
        names.append(f"p{int(view.angle)}.png")
        Image.fromarray(np.rint(np.array(view.image) * 65535).astype(np.uint16)).save(tmp_path / names[-1])
    out = tmp_path / "pebble.ply"
    args = ["fuse", *(str(tmp_path / n) for n in names), "--angles", "0,90,180,270", "-o", str(out), "--json"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["mesh"]["watertight"] and out.is_file()
    truth = synth.closed_object("pebble", size=SMALL)
    assert abs(report["mesh"]["volume"] / truth.volume - 1) < 0.05
    # the same views from a views file, one given as its 4x4 pose
    document = {"views": [{"photo": n, "angle": a} for n, a in zip(names, angles)]}
    document["views"][1] = {"photo": names[1], "pose": turntable(90).tolist()}
    (tmp_path / "views.json").write_text(json.dumps(document))
    again = tmp_path / "again.stl"
    result = CliRunner().invoke(app, ["fuse", "--views", str(tmp_path / "views.json"), "-o", str(again)])
    assert result.exit_code == 0, result.output
    assert "watertight" in result.output and again.is_file()
    # bad input: one line, exit 2, nothing written
    bad = [
        (["fuse", str(tmp_path / names[0]), "--angles", "0", "-o", str(tmp_path / "x.glb")], "at least two"),
        (["fuse", *(str(tmp_path / n) for n in names[:2]), "--angles", "0,90,180", "-o", str(tmp_path / "x.glb")], "3 angles for 2"),
        (["fuse", *(str(tmp_path / n) for n in names[:2]), "-o", str(tmp_path / "x.glb")], "--angles"),
        (["fuse", *(str(tmp_path / n) for n in names[:2]), "--angles", "0,ninety", "-o", str(tmp_path / "x.glb")], "numbers"),
        (["fuse", str(tmp_path / names[0]), "--views", str(tmp_path / "views.json"), "-o", str(tmp_path / "x.glb")], "not both"),
        (["fuse", *(str(tmp_path / n) for n in names[:2]), "--angles", "0,90", "-o", str(tmp_path / "x.xyz")], "x.xyz"),
    ]  # fmt: skip
    (tmp_path / "broken.json").write_text("{views: [")
    bad.append(
        (["fuse", "--views", str(tmp_path / "broken.json"), "-o", str(tmp_path / "x.glb")], "not valid JSON")
    )
    for args, words in bad:
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2, result.output
        assert words in result.output and result.output.count("\n") == 1, result.output
    assert not (tmp_path / "x.glb").exists()


def test_cli_warns_when_the_photos_fit_another_placement(tmp_path, monkeypatch):
    import dataclasses
    import json

    from PIL import Image
    from typer.testing import CliRunner

    import shadeform.fusion as fusion
    from shadeform.cli import app
    from shadeform.fusion import Rival

    names = []
    for view in synth.render_views("pebble", (0, 90, 180, 270), size=SMALL):
        names.append(str(tmp_path / f"p{int(view.angle)}.png"))
        Image.fromarray(np.rint(np.array(view.image) * 65535).astype(np.uint16)).save(names[-1])
    rival = Rival((0.0, 16.5, 0.0, 16.4), 1.06)
    placed = fusion.place  # the command imports it when it runs
    monkeypatch.setattr(
        fusion, "place", lambda *a, **k: dataclasses.replace(placed(*a, **k), rivals=(rival,))
    )
    args = ["fuse", *names, "--angles", "0,90,180,270", "-o", str(tmp_path / "m.ply")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    (line,) = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert (
        "view 2 turned 16 degrees, view 4 turned 16 degrees" in line
        and "add a photo between two views" in line
    )
    report = json.loads(CliRunner().invoke(app, [*args, "--json"]).output)
    assert report["rivals"] == [{"turns": [0.0, 16.5, 0.0, 16.4], "ratio": 1.06}]


@pytest.mark.parametrize(
    "flag, refine_poses",
    [
        ("--refine-poses", True),
        ("--keep-poses", False),
        ("--refine", True),
        ("--no-refine", False),
        (None, True),
    ],
)
def test_cli_refine_poses_and_its_old_names(tmp_path, flag, refine_poses):
    # parsed only: --refine/--no-refine, the old names of --refine-poses/--keep-poses, still taken
    from typer.main import get_command

    from shadeform.cli import app

    args = ["a.png", "b.png", "--angles", "0,90", "-o", str(tmp_path / "m.ply"), *([flag] if flag else [])]
    command = get_command(app).commands["fuse"]
    assert command.make_context("fuse", args).params["refine_poses"] is refine_poses


def test_the_old_keyword_refine_warns_and_gives_the_same_result():
    angles = (0, 120, 240)
    views = list(zip(true_views("ellipsoid", angles, size=SMALL), angles))
    new = place(views, refine_poses=False)
    with pytest.warns(DeprecationWarning, match="refine_poses="):
        old = place(views, refine=False)
    np.testing.assert_array_equal(np.array(old.transforms()), np.array(new.transforms()))
    mesh = shadeform.fuse(views, refine_poses=False)
    with pytest.warns(DeprecationWarning, match="fuse"):
        again = shadeform.fuse(views, refine=False)
    np.testing.assert_array_equal(again.vertices, mesh.vertices)
    np.testing.assert_array_equal(again.faces, mesh.faces)
    with pytest.raises(TypeError, match="both refine= and refine_poses="):
        place(views, refine_poses=False, refine=True)


def test_evaluate_fuse_prints_the_table():
    import json

    from typer.testing import CliRunner

    from shadeform.cli import app

    result = CliRunner().invoke(app, ["evaluate", "--fuse", "--size", "64", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["rows"]
    assert [row["object"] for row in rows] == list(synth.CLOSED_OBJECTS)
    assert all(row["watertight"] and row["chamfer"] > 0 and 0 <= row["f_score"] <= 100 for row in rows)
    lumpy = rows[synth.CLOSED_OBJECTS.index("lumpy")]
    assert lumpy["chamfer"] < 1.0 and abs(lumpy["volume_error"]) < 5  # 64 px: coarse, still close


def test_placement_puts_each_partial_model_on_the_object():
    """place + solid equal fuse, and each view's own mesh, moved by its transform, lies on the
    true surface (the app shows the partial models this way)."""
    from scipy.spatial import cKDTree

    from shadeform.fusion import place, solid
    from shadeform.mesh import to_mesh

    angles = (0, 90, 180, 270)
    recs = true_views("ellipsoid", angles)
    placement = place(list(zip(recs, angles)))
    mesh = solid(placement)
    assert np.array_equal(mesh.vertices, shadeform.fuse(list(zip(recs, angles))).vertices)
    truth = synth.closed_object("ellipsoid", size=SMALL)
    fused = cKDTree(mesh.vertices)
    for rec, transform in zip(placement.readings, placement.transforms()):
        part = to_mesh(rec, step=2)
        points = part.vertices @ transform[:3, :3].T + transform[:3, 3]
        # on the fused surface (near its vertices, which are a voxel or less apart)
        distance, _ = fused.query(points)
        assert np.median(distance) < 1.0 and np.percentile(distance, 95) < 2.0
        # and on the true object (distance ~ |F| / |grad F|; a wrong frame would be far off)
        off = np.abs(truth.implicit(points)) / np.linalg.norm(truth.gradient(points), axis=-1)
        assert np.median(off) < 1.0, np.median(off)


def test_cli_settles_the_waist_and_takes_regions_per_view(tmp_path):
    """'shadeform fuse' on the waisted object's photos: by default the side views settle the
    waist that the front and back photos leave open (said per view, the volume right); with
    --no-settle it is not; drawn in the views file (inline regions for the front, a file for the
    back) it needs no settling."""
    import json

    from PIL import Image
    from typer.testing import CliRunner

    from shadeform.cli import app

    angles = (0, 90, 180, 270)
    views = synth.render_views("waisted", angles, size=SIZE)
    names = []
    for view in views:
        names.append(f"w{int(view.angle)}.png")
        Image.fromarray(np.rint(np.array(view.image) * 65535).astype(np.uint16)).save(tmp_path / names[-1])
    truth = synth.closed_object("waisted", size=SIZE).volume
    photos = [str(tmp_path / n) for n in names]
    common = ["--angles", "0,90,180,270", "--resolution", "2", "--keep-poses", "--json"]

    def run(*args):
        result = CliRunner().invoke(app, ["fuse", *args])
        assert result.exit_code == 0, result.output
        return json.loads(result.stdout)  # stderr has the progress

    settled = run(*photos, "-o", str(tmp_path / "a.ply"), *common)
    assert [len(view["settled_concave"]) for view in settled["views"]] == [1, 0, 1, 0]
    assert abs(settled["mesh"]["volume"] / truth - 1) < 0.05
    alone = run(*photos, "-o", str(tmp_path / "b.ply"), *common, "--no-settle")
    assert all(not view["settled_concave"] for view in alone["views"])
    assert abs(settled["mesh"]["volume"] / truth - 1) < abs(alone["mesh"]["volume"] / truth - 1)
    # the waist drawn by the user: as the settled areas, inline and from a file
    front = {"regions": [{"polygon": settled["views"][0]["settled_concave"][0]["polygon"], "axis": "x"}]}
    back = {"regions": [{"polygon": settled["views"][2]["settled_concave"][0]["polygon"], "axis": "x"}]}
    (tmp_path / "back.json").write_text(json.dumps(back))
    document = {"views": [{"photo": n, "angle": a} for n, a in zip(names, angles)]}
    document["views"][0]["concave"] = front
    document["views"][2]["concave"] = "back.json"
    (tmp_path / "views.json").write_text(json.dumps(document))
    drawn = run("--views", str(tmp_path / "views.json"), "-o", str(tmp_path / "c.ply"), *common[2:])
    assert all(not view["settled_concave"] for view in drawn["views"])
    assert abs(drawn["mesh"]["volume"] / truth - 1) < 0.05


def test_views_from_opposite_sides_only_do_not_fix_the_depth():
    """Front and back views see the width and height twice and the depth never: the placement
    says so (the CLI warns), and a view from the side, or one off the line by more than a pose's
    correction, fixes it."""
    assert not place(list(zip(true_views("waisted", (0, 180)), (0, 180))), refine_poses=False).depth_fixed
    assert not place(list(zip(true_views("waisted", (0, 185)), (0, 185))), refine_poses=False).depth_fixed
    assert place(list(zip(true_views("waisted", (0, 90)), (0, 90))), refine_poses=False).depth_fixed
    assert place(
        list(zip(true_views("waisted", (0, 180, 270)), (0, 180, 270))), refine_poses=False
    ).depth_fixed


@pytest.mark.parametrize("name", ["pebble", "lumpy"])
def test_a_front_and_back_pair_keeps_its_outline_and_meets_at_its_rim(name):
    """Views from opposite sides share their outline (the same contour generator): the back view
    is moved until its rim meets the front's, so the model is as wide and tall as the
    silhouettes and as deep as the object, and no voxel off the masks is counted inside (such
    voxels made needles along the line of sight)."""
    from shadeform.fusion import solid
    from shadeform.fusion.outlines import outline_iou

    angles = (0, 180)
    views = true_views(name, angles)
    placement = place(list(zip(views, angles)))
    mesh = solid(placement)
    assert trimesh.Trimesh(mesh.vertices, mesh.faces).is_watertight
    assert min(outline_iou(mesh, placement)) >= 0.95
    # a model two thirds the size keeps about half of each outline, and is measured so
    centre = mesh.vertices.mean(axis=0)
    shrunk = dataclasses.replace(mesh, vertices=centre + (mesh.vertices - centre) * (2 / 3))
    assert max(outline_iou(shrunk, placement)) < 0.5
    rows, cols = np.nonzero(views[0].mask)
    extent = np.ptp(mesh.vertices, axis=0)
    np.testing.assert_allclose(extent[:2], [np.ptp(cols) + 1, np.ptp(rows) + 1], rtol=0.05)
    truth = synth.closed_object(name, size=SMALL)
    points, _ = truth.surface_points(20_000, seed=1)
    assert abs(extent[2] - np.ptp(points[:, 2])) <= 0.1 * np.ptp(points[:, 2]), (
        extent,
        np.ptp(points, axis=0),
    )
