"""Concave regions: parsing, round trip, every malformation, rasterisation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shadeform.errors import InputError
from shadeform.regions import Region, concave_masks, parse_regions, regions_to_json

DOC = {
    "regions": [
        {"polygon": [[2, 1], [6, 1], [6, 4], [2, 4]], "axis": "x"},
        {"polygon": [[0.5, 0.5], [3.5, 0.5], [3.5, 2.5]], "axis": "both"},
        {"polygon": [[7, 5], [9, 5], [9, 7], [7, 7]], "axis": "y"},
    ]
}


def _one(polygon=((0, 0), (4, 0), (4, 4)), axis="x"):
    return {"regions": [{"polygon": [list(p) for p in polygon], "axis": axis}]}


class TestRegion:
    def test_smoke(self):
        r = Region(polygon=[[0, 0], [1, 0], [1, 1]], axis="both")
        assert r.polygon.dtype == np.float64 and r.polygon.shape == (3, 2)
        assert not r.polygon.flags.writeable

    def test_validation(self):
        with pytest.raises(InputError, match="N >= 3"):
            Region(polygon=[[0, 0], [1, 1]], axis="x")
        with pytest.raises(InputError, match="finite"):
            Region(polygon=[[0, 0], [1, 0], [np.inf, 1]], axis="x")
        with pytest.raises(InputError, match="axis must be"):
            Region(polygon=[[0, 0], [1, 0], [1, 1]], axis="xy")


class TestParseRegions:
    def test_smoke(self):
        regions = parse_regions(DOC)
        assert len(regions) == 3 and all(isinstance(r, Region) for r in regions)

    def test_values(self):
        first, second, third = parse_regions(DOC)
        np.testing.assert_array_equal(first.polygon, [[2, 1], [6, 1], [6, 4], [2, 4]])
        assert (first.axis, second.axis, third.axis) == ("x", "both", "y")
        assert second.polygon.shape == (3, 2) and second.polygon[2, 1] == 2.5

    def test_sources_agree(self, tmp_path):
        path = tmp_path / "regions.json"
        path.write_text(json.dumps(DOC), encoding="utf-8")
        for source in (json.dumps(DOC), path):
            got = parse_regions(source)
            assert regions_to_json(got) == regions_to_json(parse_regions(DOC))

    def test_empty_list(self):
        assert parse_regions({"regions": []}) == ()

    def test_tuples_from_python(self):
        (r,) = parse_regions({"regions": [{"polygon": ((0, 0), (1, 0), (1, 1)), "axis": "y"}]})
        assert r.polygon.shape == (3, 2)

    def test_invalid_json_reports_position(self):
        text = '{"regions": [\n  {"polygon": [[0, 0], [1, 0], [1, 1]] "axis": "x"}\n]}'
        with pytest.raises(InputError, match="not valid JSON: .* at line 2, column 40"):
            parse_regions(text)

    def test_path_like_string_hint(self):
        with pytest.raises(InputError, match="pass a pathlib.Path"):
            parse_regions("regions.json")

    def test_file_not_found(self, tmp_path):
        with pytest.raises(InputError, match="not found"):
            parse_regions(tmp_path / "missing.json")

    def test_folder(self, tmp_path):
        with pytest.raises(InputError, match="is a folder"):
            parse_regions(tmp_path)

    def test_invalid_json_in_file(self, tmp_path):
        path = tmp_path / "bad.json"
        path.write_text('{"regions": [', encoding="utf-8")
        message = r"bad\.json' is not valid JSON: .* at line 1, column 14"
        with pytest.raises(InputError, match=message):
            parse_regions(path)

    @pytest.mark.parametrize(
        "document, message",
        [
            ({}, "no 'regions' key"),
            ({"region": []}, "no 'regions' key"),
            ({"regions": {"polygon": []}}, "'regions' .* must be a list, got an object"),
            ({"regions": ["x"]}, "each region must be an object .* in region 1"),
            ({"regions": [{"axis": "x"}]}, "missing 'polygon' in region 1"),
            ({"regions": [{"polygon": [[0, 0], [1, 0], [1, 1]]}]}, "missing 'axis' in region 1"),
            (_one(((0, 0), (1, 1))), "at least 3 points, got 2 in region 1"),
            ({"regions": [{"polygon": "square", "axis": "x"}]}, "list of \\[x, y\\] points"),
            (_one(((0, 0), (1, 0), (1,))), "point 3 must be \\[x, y\\], got \\[1\\]"),
            (_one(((0, 0), (1, "a"), (1, 1))), 'point 2 has a non-numeric coordinate "a"'),
            (_one(((0, 0), (1, None), (1, 1))), "non-numeric coordinate null"),
            (_one(((0, 0), (True, 0), (1, 1))), "non-numeric coordinate true"),
            (_one(((0, 0), (1, 0), (1, float("nan")))), "point 3 has a non-finite coordinate"),
            (_one(((0, 0), (1, 0), (float("inf"), 1))), "non-finite coordinate"),
            (_one(axis="z"), "axis must be 'x', 'y' or 'both', got 'z' in region 1"),
            (_one(axis=1), "axis must be 'x', 'y' or 'both', got 1 in region 1"),
        ],
    )
    def test_malformed(self, document, message):
        with pytest.raises(InputError, match=message) as info:
            parse_regions(document)
        assert "\n" not in str(info.value)

    def test_names_the_region(self):
        doc = {"regions": [DOC["regions"][0], {"polygon": [[0, 0], [1, 0], [1, 1]], "axis": "z"}]}
        with pytest.raises(InputError, match="got 'z' in region 2"):
            parse_regions(doc)

    def test_nan_literal_in_text(self):
        text = '{"regions": [{"polygon": [[0, 0], [1, 0], [NaN, 1]], "axis": "x"}]}'
        with pytest.raises(InputError, match="non-finite"):
            parse_regions(text)

    def test_top_level_not_object(self):
        with pytest.raises(InputError, match="must be an object, got a list"):
            parse_regions("[1, 2]")

    def test_wrong_source_type(self):
        with pytest.raises(InputError, match="dict, a JSON string or a pathlib.Path"):
            parse_regions(42)


class TestRegionsToJson:
    def test_smoke(self):
        assert regions_to_json(()) == {"regions": []}

    def test_round_trip(self):
        regions = parse_regions(DOC)
        document = regions_to_json(regions)
        assert document == json.loads(json.dumps(DOC))  # ints compare equal to floats
        again = parse_regions(json.dumps(document))
        for a, b in zip(regions, again):
            np.testing.assert_array_equal(a.polygon, b.polygon)
            assert a.axis == b.axis

    def test_file_round_trip(self, tmp_path):
        path = Path(tmp_path) / "out.json"
        path.write_text(json.dumps(regions_to_json(parse_regions(DOC))), encoding="utf-8")
        assert regions_to_json(parse_regions(path)) == regions_to_json(parse_regions(DOC))


class TestConcaveMasks:
    def test_smoke(self):
        cx, cy = concave_masks((), (4, 5))
        assert cx.shape == cy.shape == (4, 5) and cx.dtype == bool
        assert not cx.any() and not cy.any()

    def test_square_by_hand(self):
        # x = columns 2..6, y = rows 1..4; pixel centres on the boundary are inside.
        (square,) = parse_regions(_one(((2, 1), (6, 1), (6, 4), (2, 4)), axis="x"))
        cx, cy = concave_masks([square], (8, 10))
        expected = np.zeros((8, 10), bool)
        expected[1:5, 2:7] = True
        np.testing.assert_array_equal(cx, expected)
        assert not cy.any()

    def test_axis_mapping(self):
        cx, cy = concave_masks(parse_regions(DOC), (10, 12))
        square_x = np.zeros((10, 12), bool)
        square_x[1:5, 2:7] = True
        square_y = np.zeros((10, 12), bool)
        square_y[5:8, 7:10] = True
        # The "both" triangle (0.5, 0.5)-(3.5, 0.5)-(3.5, 2.5) lies under the line
        # y = 0.5 + 2 (x - 0.5) / 3: it holds the centres (x, y) = (2, 1), (3, 1), (3, 2)
        # but not (1, 1), where the line is at y = 0.83.
        triangle = np.zeros((10, 12), bool)
        triangle[1, 2:4] = True
        triangle[2, 3] = True
        np.testing.assert_array_equal(cx, square_x | triangle)
        np.testing.assert_array_equal(cy, square_y | triangle)

    def test_clipped_and_outside(self):
        partly = Region(polygon=[[-5, -5], [2, -5], [2, 1], [-5, 1]], axis="y")
        outside = Region(polygon=[[20, 20], [30, 20], [30, 30]], axis="both")
        far = Region(polygon=[[-1e9, -1e9], [-1e9 + 1, -1e9], [-1e9, -1e9 + 1]], axis="x")
        cx, cy = concave_masks([partly, outside, far], (6, 6))
        expected = np.zeros((6, 6), bool)
        expected[0:2, 0:3] = True
        np.testing.assert_array_equal(cy, expected)
        assert not cx.any()

    def test_image_shape_with_channels(self):
        (square,) = parse_regions(_one(((0, 0), (2, 0), (2, 2), (0, 2)), axis="both"))
        cx, cy = concave_masks([square], (4, 4, 3))
        assert cx.shape == (4, 4) and cx.sum() == 9 and np.array_equal(cx, cy)

    def test_bad_shape(self):
        with pytest.raises(InputError, match="shape"):
            concave_masks((), (0, 4))
        with pytest.raises(InputError, match="shape"):
            concave_masks((), (4,))
