"""The method benchmark's harness (benchmarks/bench_methods.py) on a tiny grid."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

import shadeform
from shadeform import metrics, solvers, synth
from shadeform.solvers import solver_names

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_methods.py"
SIZE = 32


def _load():
    spec = importlib.util.spec_from_file_location("bench_methods", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


bench = _load()
LIGHTS = (bench.LIGHTS[0], bench.LIGHTS[1])  # +z and slant 30
NOISES = (0.0,)


@pytest.fixture(scope="module")
def rows():
    # no warm-up: timings do not matter here, only the table
    return bench.run_grid(size=SIZE, repeats=1, scenes=("sphere",), lights=LIGHTS, noises=NOISES, warm=False)


class TestMethods:
    def test_every_solver_and_the_2002_variant(self):
        labels = [label for label, _ in bench.methods()]
        solvers = solver_names()
        assert set(solvers) <= set(labels) and "auto" not in labels
        assert dict(bench.methods())[bench.LEGACY] == {
            "solver": "propagation",
            "refine": 0,
            "integrator": "paths",
        }
        assert len(labels) == len(solvers) + 1

    def test_picks_up_a_new_solver(self, registries):
        solvers.register(
            solvers.Solver(
                "newcomer",
                "shadeform.solvers.propagation:solve",
                integrator="paths",
                description="a solver registered by the test",
            )
        )
        assert ("newcomer", {"solver": "newcomer"}) in bench.methods()


class TestGrid:
    def test_rows(self, rows):
        expected = {
            (label, "sphere", light, noise)
            for label, _ in bench.methods()
            for light, _ in LIGHTS
            for noise in NOISES
        }
        got = [(row.method, row.scene, row.light, row.noise) for row in rows]
        assert len(got) == len(expected) and set(got) == expected

    def test_finite_numbers_where_a_method_ran(self, rows):
        ran = [row for row in rows if row.available]
        assert ran
        for row in ran:
            assert math.isfinite(row.depth_pct) and row.depth_pct >= 0
            assert math.isfinite(row.angle_deg) and 0 <= row.angle_deg <= 180
            assert row.seconds > 0 and row.runs == 1 and row.object_pixels > 0

    def test_eikonal_is_na_under_oblique_light_only(self, rows):
        eikonal = {row.light: row for row in rows if row.method == "eikonal" and row.noise == 0}
        assert eikonal["+z"].available
        assert not eikonal["slant 30°"].available
        assert "eikonal" in eikonal["slant 30°"].note and math.isnan(eikonal["slant 30°"].depth_pct)
        # propagation handles every light
        assert all(row.available for row in rows if row.method.startswith("propagation"))

    def test_errors_are_those_of_evaluate(self, rows):
        # the numbers in the table are the metrics of a direct reconstruct call
        light_label, light = LIGHTS[1]
        scene = synth.scene("sphere", size=SIZE, light=light, noise=NOISES[-1], seed=bench.SEED)
        rec = shadeform.reconstruct(
            scene.image,
            mask=scene.mask,
            light=scene.light,
            solver="propagation",
            concave=synth.concave_regions("sphere", size=SIZE),
        )
        row = next(
            r for r in rows if r.method == "propagation" and r.light == light_label and r.noise == NOISES[-1]
        )
        assert row.depth_pct == pytest.approx(metrics.depth_error(rec.depth, scene.depth, fit="offset"))
        assert row.angle_deg == pytest.approx(metrics.angular_error(rec.normals, scene.normals))

    def test_other_errors_propagate(self, monkeypatch):
        def broken(scene, kwargs, size):
            raise RuntimeError("bug")

        monkeypatch.setattr(bench, "solve", broken)
        with pytest.raises(RuntimeError, match="bug"):
            bench.run_grid(
                size=SIZE,
                repeats=1,
                scenes=("sphere",),
                lights=LIGHTS[:1],
                noises=(0.0,),
                chosen=[("propagation", {"solver": "propagation"})],
                warm=False,
            )


class TestMemory:
    def test_peak_memory(self):
        found = bench.peak_memory(bench.LEGACY, dict(bench.methods())[bench.LEGACY], "+z", size=SIZE)
        assert found.light == "+z" and found.scene == "sphere"
        # at least the (H, W, 3) float64 normals it returns are allocated
        assert found.traced >= SIZE * SIZE * 3 * 8
        assert bench.peak_memory("eikonal", {"solver": "eikonal"}, "slant 30°", size=SIZE) is None


class TestTiming:
    def test_budget_stops_repeats(self):
        calls = []
        result, seconds, runs = bench.timed(lambda: calls.append(1) or len(calls), 5, 0.0)
        assert runs == 1 and len(calls) == 1 and result == 1 and seconds >= 0
        _, _, runs = bench.timed(lambda: None, 4, math.inf)
        assert runs == 4


class TestReport:
    def test_tables(self, rows, tmp_path):
        memory = [bench.Memory("eikonal", "sphere", "+z", traced=2**20, rss=None)]
        text = bench.write_results(
            rows, memory, tmp_path, size=SIZE, repeats=1, budget=math.inf, wall=1.0, pictures=False
        )
        assert (tmp_path / "methods.md").read_text(encoding="utf-8") == text
        assert list(tmp_path.iterdir()) == [tmp_path / "methods.md"]
        full = text.split("## Full table, light slant 30°")[1]
        sphere_lines = [line for line in full.splitlines() if line.startswith("| sphere |")]
        assert len(sphere_lines) == len(NOISES)
        eikonal_at = 1 + 1 + 3 * [label for label, _ in bench.methods()].index("eikonal") + 1
        assert [cell.strip() for cell in sphere_lines[0].split("|")][eikonal_at] == "n/a"
        best = bench.best_method(rows, "+z", 0.0)
        assert (
            f"Best measured for +z (lowest median depth error over the 1 scenes, noise 0%): **{best}**"
            in text
        )
        assert "| eikonal | slant 30° | n/a |" in text
        # the default's choice is shown beside the measured best
        assert f'`solver="auto"` picks {solvers.choose(np.array([0.0, 0.0, 1.0])).name}' in text

    def test_replot_from_saved_rows(self, rows, tmp_path):
        from PIL import Image

        saved = tmp_path / "rows.json"
        run = {"size": SIZE, "repeats": 1, "budget": math.inf, "wall": 1.0}
        bench.save_rows(saved, rows, [], run)
        loaded, memory, run_back = bench.load_rows(saved)
        assert run_back == run and memory == []
        # the same rows, NaN of the n/a cells included
        assert len(loaded) == len(rows)
        for back, row in zip(loaded, rows):
            assert all(_same(getattr(back, f), getattr(row, f)) for f in row.__dataclass_fields__)
        out = tmp_path / "out"
        assert bench.main(["--replot", str(saved), "--out", str(out)]) == 0
        for name in ("methods_depth.png", "methods_angle.png", "methods_noise.png"):
            with Image.open(out / name) as picture:
                assert picture.size[0] > 400 and picture.size[1] > 300
        assert (
            (out / "methods.md").read_text(encoding="utf-8").startswith("# Methods on the synthetic scenes")
        )
        # the showcase is the vase, not in this grid
        assert not (out / "showcase.png").exists()


def _same(a, b) -> bool:
    return a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


def test_best_by_scene_picks_the_lowest_depth_error():
    row = bench.Row
    rows = [
        row("a", "s", "+z", 0.0, 2.0, 1.0, 0.1, 1, 10),
        row("b", "s", "+z", 0.0, 1.0, 5.0, 0.1, 1, 10),
        row("c", "s", "+z", 0.0, math.nan, math.nan, math.nan, 0, 10, note="refuses"),
    ]
    assert bench.best_by_scene(rows, 0.0)[("s", "+z")].method == "b"
    assert bench.best_method(rows, "+z", 0.0) == "b"
    assert np.isnan(rows[2].depth_pct)
