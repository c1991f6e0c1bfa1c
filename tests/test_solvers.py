"""The solver registry: one module + one ``register`` line makes a solver available everywhere.

The proof: a small solver written here, registered inside the test, runs through the library,
the CLI and the server without touching any of them; and a newcomer's solver with an option of its
own (``toy``, ``strength``) is listed, run, evaluated and offered with that option.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

import shadeform
from shadeform import metrics, synth
from shadeform.errors import InputError
from shadeform.registry import Option, Registry
from shadeform.solvers import AUTO, Problem, Solution, Solver, available_solvers, choose, get_solver
from shadeform.solvers.propagation import image_gradient


def gradient_solve(problem: Problem) -> Solution:
    """A small solver: each normal on its cone, tilted against the brightness gradient (a convex
    object), depth by the integrator. Reads the problem's image, mask, light and albedo."""
    gx, gy = image_gradient(problem.image / problem.albedo, problem.mask)
    length = np.hypot(gx, gy)
    cos_theta = problem.cos_theta
    sin_theta = np.sqrt(1.0 - cos_theta**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        tilt = np.where((length > 0)[..., None], -np.stack([gx, gy], axis=-1) / length[..., None], 0.0)
    normals = np.dstack([sin_theta[..., None] * tilt, cos_theta])
    normals[~problem.mask] = (0.0, 0.0, 1.0)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    problem.lap("normals")
    return Solution(normals, problem.integrate(normals), {"gradient_pixels": int(np.count_nonzero(length))})


TINY = Solver(
    "gradient",
    gradient_solve,
    lights="frontal",
    integrator="poisson",
    description="normals tilted against the brightness gradient (a test solver)",
)


@pytest.fixture
def tiny(registries):
    registries[0].register(TINY)
    return TINY


def toy_solve(problem: Problem) -> Solution:
    """The newcomer's solver: the gradient solver's normals, its depth stretched by its option."""
    solved = gradient_solve(problem)
    strength = problem.options["strength"]
    return Solution(solved.normals, solved.depth * strength, {"strength": strength})


STRENGTH = Option("strength", float, 1.0, "how much the depth is stretched")
TOY = Solver(
    "toy",
    toy_solve,
    integrator="poisson",
    description="a newcomer's solver with an option of its own",
    options=(STRENGTH,),
)


@pytest.fixture
def toy(registries):
    registries[0].register(TOY)
    return TOY


class TestRegistry:
    def test_builtin_solvers_listed_with_auto_first(self):
        methods = available_solvers()
        assert list(methods)[0] == AUTO
        assert {"propagation", "eikonal", "oblique"} <= set(methods)
        assert all(isinstance(text, str) and text and "\n" not in text for text in methods.values())

    def test_unknown_method_lists_the_registered(self):
        with pytest.raises(InputError, match="unknown solver 'magic'; choose one of: propagation, eikonal"):
            get_solver("magic")
        # reconstruct takes "auto" too, its default, and says so
        with pytest.raises(InputError, match="unknown solver 'magic'; choose one of: auto, propagation"):
            shadeform.reconstruct(np.ones((8, 8)), solver="magic")

    def test_auto_rule_is_lights_then_noise_then_rank(self):
        frontal, oblique = np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.0, 0.866])
        assert choose(frontal).name == "eikonal"
        assert choose(frontal, noise=0.01).name == "oblique"
        assert choose(oblique).name == "oblique"
        assert choose(None).name == "oblique"

    def test_auto_takes_the_guided_photo_solver_for_noisy_images_with_outlying_detail(self):
        frontal, oblique = np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.0, 0.866])
        for light in (frontal, oblique, None):
            assert choose(light, noise=0.01, outliers=0.02).name == "guided"
            assert choose(light, noise=0.01, outliers=0.001).name == "oblique"  # render plus noise
        # a clean image's detail is its shading's curvature: its outliers say nothing
        assert choose(frontal, noise=0.001, outliers=0.5).name == "eikonal"
        assert "photographs" in available_solvers()[AUTO]

    def test_a_ranked_solver_is_chosen_by_auto(self, registries):
        registries[0].register(
            Solver("first", gradient_solve, integrator="poisson", auto=-1, description="ranked first")
        )
        assert choose(np.array([0.5, 0.0, 0.866])).name == "first"
        assert "first" in available_solvers()[AUTO]

    def test_a_record_must_be_complete(self):
        with pytest.raises(ValueError, match="identifier"):
            Solver("two words", gradient_solve, integrator="paths", description="x")
        with pytest.raises(ValueError, match="lights"):
            Solver("x", gradient_solve, lights="left", integrator="paths", description="x")
        with pytest.raises(ValueError, match="depth"):
            Solver("x", gradient_solve, description="no integrator and no depth of its own")


class TestNewSolverEverywhere:
    def test_library(self, tiny, sphere64):
        scene = sphere64
        assert "gradient" in available_solvers()
        rec = shadeform.reconstruct(scene.image, mask=scene.mask, solver="gradient")
        assert rec.info["solver"] == "gradient" and rec.info["integrator"] == "poisson"
        assert rec.info["gradient_pixels"] > 0.9 * scene.mask.sum()
        assert metrics.angular_error(rec.normals, scene.normals, scene.mask) < 3.0
        assert metrics.depth_error(rec.depth, scene.depth, fit="offset") < 3.0
        assert np.isnan(rec.depth[~scene.mask]).all()
        # its own records are honoured: light, integrator, preview budget
        with pytest.raises(InputError, match="light"):
            shadeform.reconstruct(scene.image, mask=scene.mask, solver="gradient", light=(0.5, 0, 0.866))
        other = shadeform.reconstruct(scene.image, mask=scene.mask, solver="gradient", integrator="fourier")
        assert other.info["integrator"] == "fourier"
        from shadeform.coarse import reconstruct_preview

        quick = reconstruct_preview(scene.image, mask=scene.mask, step=2, solver="gradient")
        assert quick.info["solver"] == "gradient" and quick.info["preview_step"] == 2

    def test_cli(self, tiny, sphere64, cli, tmp_path):
        listed = cli("solvers", "--json")
        assert listed.exit_code == 0, listed.output
        rows = {row["name"]: row for row in json.loads(listed.stdout)["solvers"]}
        assert rows["gradient"]["description"] == TINY.description and rows["gradient"]["depth"] == "poisson"
        photo = tmp_path / "sphere.png"
        Image.fromarray(np.rint(sphere64.image * 255).astype(np.uint8)).save(photo)
        result = cli("reconstruct", photo, "-o", tmp_path / "sphere.ply", "--solver", "gradient", "--json")
        assert result.exit_code == 0, result.output
        assert json.loads(result.stdout)["info"]["solver"] == "gradient"
        assert (tmp_path / "sphere.ply").stat().st_size > 0

    def test_server(self, tiny):
        from shadeform.app.server import create_app

        with TestClient(create_app(), base_url="http://127.0.0.1:8000") as client:
            options = client.get("/api/options").json()
            assert {"name": "gradient", "description": TINY.description} in options["solvers"]
            image = client.post("/api/examples/synth:sphere?size=48").json()
            response = client.post(
                "/api/reconstruct",
                json={
                    "image_id": image["image_id"],
                    "request_id": 1,
                    "params": {"solver": "gradient", "step": 2},
                },
            )
            assert response.status_code == 200, response.text
            assert response.json()["info"]["solver"] == "gradient"


class TestNewcomersRecipe:
    """A solver with its own option, registered from outside the package, is everywhere."""

    def test_library(self, toy, sphere64):
        scene = sphere64
        assert "toy" in available_solvers()
        plain = shadeform.reconstruct(scene.image, mask=scene.mask, solver="toy")
        assert plain.info["strength"] == 1.0 and plain.info["solver_options"] == {"strength": 1.0}
        twice = shadeform.reconstruct(
            scene.image, mask=scene.mask, solver="toy", solver_options={"strength": "2"}
        )
        assert twice.info["solver_options"] == {"strength": 2.0}
        np.testing.assert_allclose(twice.depth, 2 * plain.depth, rtol=1e-6, atol=1e-6, equal_nan=True)
        with pytest.raises(InputError, match="solver 'toy' has no option 'power'; its options: strength"):
            shadeform.reconstruct(scene.image, mask=scene.mask, solver="toy", solver_options={"power": 2})
        with pytest.raises(InputError, match="option 'strength' must be a finite number, got 'lots'"):
            shadeform.reconstruct(
                scene.image, mask=scene.mask, solver="toy", solver_options={"strength": "lots"}
            )
        # the built-in solvers have no options, and say so
        with pytest.raises(InputError, match="solver 'eikonal' has no option 'strength'; its options: none"):
            shadeform.reconstruct(
                scene.image, mask=scene.mask, solver="eikonal", solver_options={"strength": 2}
            )
        assert "solver_options" not in shadeform.reconstruct(scene.image, mask=scene.mask).info

    def test_cli(self, toy, sphere64, cli, tmp_path):
        listed = cli("solvers", "--json")
        assert listed.exit_code == 0, listed.output
        rows = {row["name"]: row for row in json.loads(listed.stdout)["solvers"]}
        assert rows["toy"]["options"] == [
            {"name": "strength", "type": "float", "default": 1.0, "help": STRENGTH.help}
        ]
        assert "options" not in rows["eikonal"]
        table = cli("solvers")
        assert "--option strength=1.0 (float): how much the depth is stretched" in table.stdout
        photo = tmp_path / "sphere.png"
        Image.fromarray(np.rint(sphere64.image * 255).astype(np.uint8)).save(photo)
        mesh = tmp_path / "sphere.ply"
        result = cli("reconstruct", photo, "-o", mesh, "--solver", "toy", "--option", "strength=2", "--json")
        assert result.exit_code == 0, result.output
        info = json.loads(result.stdout)["info"]
        assert info["solver"] == "toy" and info["solver_options"] == {"strength": 2.0}
        for wrong, message in (("strength", "NAME=VALUE"), ("power=2", "no option 'power'")):
            refused = cli(
                "reconstruct", photo, "-o", tmp_path / "x.ply", "--solver", "toy", "--option", wrong
            )
            assert refused.exit_code == 2 and message in refused.output
        evaluated = cli(
            "evaluate", "--size", "32", "--scenes", "sphere", "--solvers", "toy,eikonal", "--json"
        )
        assert evaluated.exit_code == 0, evaluated.output
        rows = json.loads(evaluated.stdout)["rows"]
        assert [row["label"] for row in rows] == ["toy", "eikonal"]
        assert rows[0]["solver_options"] == {"strength": 1.0} and rows[0]["angular_error_deg"] < 5
        assert "toy" in cli("evaluate", "--size", "8", "--solvers", "nothing").output

    def test_server(self, toy):
        from shadeform.app.server import create_app

        with TestClient(create_app(), base_url="http://127.0.0.1:8000") as client:
            methods = {m["name"]: m for m in client.get("/api/options").json()["solvers"]}
        assert methods["toy"] == {
            "name": "toy",
            "description": TOY.description,
            "options": [{"name": "strength", "type": "float", "default": 1.0, "help": STRENGTH.help}],
        }
        assert "options" not in methods["eikonal"]  # sent only when a solver has some

    def test_the_old_names_still_work_and_warn(self, toy, sphere64, cli):
        """``method=``, ``method_options=``, ``--method``, ``shadeform methods`` and
        ``available_methods``: the names before the rename, kept for one release."""
        scene = sphere64
        now = shadeform.reconstruct(
            scene.image, mask=scene.mask, solver="toy", solver_options={"strength": 2}
        )
        with pytest.warns(DeprecationWarning, match="now reconstruct\\(solver="):
            old = shadeform.reconstruct(
                scene.image, mask=scene.mask, method="toy", method_options={"strength": 2}
            )
        np.testing.assert_array_equal(old.depth, now.depth)
        assert old.info["solver"] == "toy" and old.info["solver_options"] == {"strength": 2.0}
        with pytest.raises(TypeError, match="both method= and solver="):
            shadeform.reconstruct(scene.image, mask=scene.mask, method="toy", solver="toy")
        with pytest.warns(DeprecationWarning, match="available_solvers"):
            assert shadeform.available_methods() == available_solvers()
        listed = cli("methods", "--json")
        assert listed.exit_code == 0 and "toy" in {
            row["name"] for row in json.loads(listed.stdout)["solvers"]
        }
        assert "methods" not in cli("--help").stdout  # hidden: only the new name is offered

    def test_projects_saved_with_the_old_name_open(self):
        from shadeform.app.schema import ReconstructParams

        assert ReconstructParams.model_validate({"method": "eikonal"}).solver == "eikonal"
        assert ReconstructParams.model_validate({"solver": "eikonal"}).model_dump()["solver"] == "eikonal"


class TestGenericRegistry:
    def test_options_read_text_as_their_types(self):
        assert Option("n", int, 3, "x").parse("4") == 4 and Option("n", int, 3, "x").parse(5.0) == 5
        assert Option("on", bool, False, "x").parse("yes") is True
        assert Option("on", bool, "true", "x").default is True
        assert Option("w", str, "a", "x").parse("b c") == "b c"
        with pytest.raises(InputError, match="option 'n' must be a whole number, got 2.5"):
            Option("n", int, 3, "x").parse(2.5)
        with pytest.raises(InputError, match="true or false"):
            Option("on", bool, False, "x").parse("maybe")
        with pytest.raises(ValueError, match="type"):
            Option("n", list, [], "x")

    def test_entries_by_name_in_order_and_restored(self):
        registry = Registry("solver", Solver)
        with pytest.raises(TypeError, match="register expects a Solver, got str"):
            registry.register("tiny")
        registry.register(TINY)
        with registry.restored():
            registry.register(TOY)
            assert registry.names() == ("gradient", "toy") and "toy" in registry
            assert registry.settle("toy", {"strength": 3}) == {"strength": 3.0}
        assert list(registry) == ["gradient"] and len(registry) == 1
        with pytest.raises(InputError, match="unknown solver 'toy'; choose one of: gradient"):
            registry.get("toy")


class TestSolverContract:
    def test_problem_is_what_reconstruct_prepared(self, registries, sphere64):
        seen = {}

        def spy(problem: Problem) -> Solution:
            seen["problem"] = problem
            return Solution(np.tile([0.0, 0.0, 1.0], problem.mask.shape + (1,)), np.zeros(problem.mask.shape))

        registries[0].register(Solver("spy", spy, depth="zero", description="records its problem"))
        scene = sphere64
        regions = synth.concave_regions("bowl", size=64)
        rec = shadeform.reconstruct(
            scene.image, mask=scene.mask, solver="spy", references=[(32, 30)], concave=regions, refine=2
        )
        problem = seen["problem"]
        assert problem.given == 1 and problem.main == (32, 30) and problem.references[0].normal is None
        assert problem.albedo == pytest.approx(scene.image.max())
        assert problem.concave_x.any() and (problem.concave_x == problem.concave_y).all()
        assert problem.refine == 2 and problem.integrator is None and problem.noise is None
        assert rec.info["integrator"] == "zero" and rec.info["references"][0] == (32, 30)
