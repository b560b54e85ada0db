"""The object catalogue: exact outlines, names, rig directions and user object files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from unitac_rig.errors import ConfigError, UsageError
from unitac_rig.rig.objects import (
    get_object,
    interior_angles_deg,
    list_objects,
    load_object_file,
    offset_polygon_inward,
    pad_side_direction,
)

PAPER_IDS = ["circle_pla", "circle_tpu", "square_pla", "square_tpu", "hex_pla", "hex_tpu", "irregular_pla"]


def test_catalogue_holds_the_paper_objects_in_order() -> None:
    assert [o.id for o in list_objects()] == PAPER_IDS


def test_unknown_object_is_a_usage_error_that_lists_the_ids() -> None:
    with pytest.raises(UsageError) as info:
        get_object("dodecahedron")
    assert info.value.hint is not None
    for object_id in PAPER_IDS:
        assert object_id in info.value.hint


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("cylinder_PLA", "circle_pla"),
        ("oblong_tpu", "square_tpu"),
        ("Hexagonal_PLA", "hex_pla"),
        ("arbitrary", "irregular_pla"),
    ],
)
def test_authors_names_resolve_to_our_ids(name: str, expected: str) -> None:
    assert get_object(name).id == expected


def test_only_the_irregular_prism_is_swept_four_times_and_kept_out_of_training() -> None:
    for obj in list_objects():
        if obj.id == "irregular_pla":
            assert obj.rotations_deg == (0.0, 90.0, 180.0, 270.0)
            assert not obj.in_autoencoder_training
        else:
            assert obj.rotations_deg == (0.0,)
            assert obj.in_autoencoder_training


def test_outlines_match_the_cad_numbers() -> None:
    # square: side 35.355 (half 17.678), circumradius 25; hexagon: circumradius 25, apothem 21.651
    square = get_object("square_pla")
    assert np.allclose(np.abs(square.outer_mm), 25 / math.sqrt(2), atol=1e-5)
    hexagon = get_object("hex_tpu")
    assert np.allclose(np.linalg.norm(hexagon.outer_mm, axis=1), 25.0, atol=1e-5)
    assert np.linalg.norm(hexagon.outline_hit(np.array([0.0, -1.0]))) == pytest.approx(25 * math.sqrt(3) / 2, abs=1e-5)
    circle = get_object("circle_pla")
    assert circle.radius_mm == 25.0
    assert np.allclose(np.linalg.norm(circle.outer_mm, axis=1), 25.0)
    assert np.allclose(np.linalg.norm(circle.inner_mm, axis=1), 22.5)


def test_irregular_prism_has_the_papers_corners_and_a_25_sin40_incircle() -> None:
    obj = get_object("irregular_pla")
    assert sorted(np.round(interior_angles_deg(obj.outer_mm)).tolist()) == [80, 100, 120, 120, 140, 160]
    # every edge is tangent to the incircle: the ray along each edge normal hits it at 25 sin 40 deg
    for normal_deg in (50, 130, 230, 290, 310, 350):
        d = np.array([math.cos(math.radians(normal_deg)), math.sin(math.radians(normal_deg))])
        assert np.linalg.norm(obj.outline_hit(d)) == pytest.approx(25 * math.sin(math.radians(40)), abs=1e-4)


def test_inner_outline_is_the_outer_moved_in_by_the_wall() -> None:
    for object_id in ("square_pla", "hex_pla", "irregular_pla"):
        obj = get_object(object_id)
        assert obj.wall_mm == 2.5
        assert np.allclose(offset_polygon_inward(obj.outer_mm, obj.wall_mm), obj.inner_mm, atol=1e-4)


def test_pad_direction_follows_the_rig_convention() -> None:
    # angle 0: the pad comes from -y (base) = -z (CAD); +45: from (sin45, -cos45)
    assert np.allclose(pad_side_direction(0, 0), [0.0, -1.0])
    assert np.allclose(pad_side_direction(45, 0), [math.sqrt(0.5), -math.sqrt(0.5)])
    # the object turned +90 deg (CCW from above): the pad at angle 0 now sees what sat at +x of the CAD frame
    assert np.allclose(pad_side_direction(0, 90), [-1.0, 0.0], atol=1e-12)


def test_square_at_45_deg_is_hit_on_its_corner() -> None:
    hit = get_object("square_pla").outline_hit(pad_side_direction(45, 0))
    assert np.allclose(hit, [17.67767, -17.67767], atol=1e-5)


# ---- object files -----------------------------------------------------------------------------------------


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_toml_polygon_file_loads_with_inner_outline_and_material(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        "tri.toml",
        'id = "tri_tpu"\nmaterial = "tpu"\nwall_mm = 2.0\n'
        "outline_mm = [[20.0, -10.0], [0.0, 20.0], [-20.0, -10.0]]\n"  # clockwise: gets reordered
        "rotations_deg = [0, 120]\n",
    )
    obj = load_object_file(path)
    assert obj.material == "TPU" and obj.material_params.name == "TPU"
    assert obj.rotations_deg == (0.0, 120.0)
    # CCW now, and the inner triangle's edges lie 2 mm inside
    assert interior_angles_deg(obj.outer_mm).sum() == pytest.approx(180.0)
    assert np.linalg.norm(obj.outline_hit(np.array([0.0, -1.0]))) == pytest.approx(10.0)
    assert obj.inner_mm[:, 1].min() == pytest.approx(-8.0)


def test_json_circle_file_loads(tmp_path: Path) -> None:
    path = _write(tmp_path, "c.json", json.dumps({"id": "tube30", "material": "PLA", "radius_mm": 30, "wall_mm": 3}))
    obj = load_object_file(path)
    assert obj.radius_mm == 30
    assert np.allclose(np.linalg.norm(obj.inner_mm, axis=1), 27.0)


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"id": "a", "material": "PLA", "radius_mm": 10, "wall_mm": 1, "colour": "red"}, "colour"),
        ({"id": "a", "material": "steel", "radius_mm": 10, "wall_mm": 1}, "material"),
        ({"id": "a", "material": "PLA", "radius_mm": 10}, "wall_mm"),
        ({"id": "a", "material": "PLA", "radius_mm": -1, "wall_mm": 1}, "radius_mm"),
        ({"id": "A B", "material": "PLA", "radius_mm": 10, "wall_mm": 1}, "id"),
    ],
)
def test_bad_object_files_name_the_field(tmp_path: Path, body: dict[str, object], field: str) -> None:
    path = _write(tmp_path, "bad.json", json.dumps(body))
    with pytest.raises(ConfigError, match=field):
        load_object_file(path)


@pytest.mark.parametrize(
    "body",
    [
        {"id": "a", "material": "PLA", "radius_mm": 10, "outline_mm": [[1, 0], [0, 1], [-1, 0]], "wall_mm": 1},
        {"id": "a", "material": "PLA", "radius_mm": 10, "wall_mm": 12},
        # the origin is outside this triangle: a press aimed at the axis would miss it
        {"id": "a", "material": "PLA", "outline_mm": [[10, 10], [20, 10], [15, 20]], "wall_mm": 1},
        {"id": "a", "material": "PLA", "outline_mm": [[20, -10], [0, 20], [-20, -10]], "wall_mm": 11},
    ],
)
def test_contradictory_geometry_is_a_config_error(tmp_path: Path, body: dict[str, object]) -> None:
    with pytest.raises(ConfigError):
        load_object_file(_write(tmp_path, "bad.json", json.dumps(body)))


def test_broken_syntax_and_suffix_are_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="TOML"):
        load_object_file(_write(tmp_path, "x.toml", "id = "))
    with pytest.raises(ConfigError, match=r"toml or \.json"):
        load_object_file(_write(tmp_path, "x.yaml", "id: a"))
    with pytest.raises(ConfigError, match="cannot read"):
        load_object_file(tmp_path / "missing.toml")


def test_extra_files_join_the_catalogue_and_clashes_are_refused(tmp_path: Path) -> None:
    good = _write(tmp_path, "tube.json", json.dumps({"id": "tube", "material": "PLA", "radius_mm": 20, "wall_mm": 2}))
    assert get_object("tube", [good]).id == "tube"
    assert [o.id for o in list_objects([good])][-1] == "tube"
    clash = _write(
        tmp_path,
        "c.json",
        json.dumps({"id": "mine", "aliases": ["oblong_pla"], "material": "PLA", "radius_mm": 9, "wall_mm": 1}),
    )
    with pytest.raises(ConfigError, match="oblong_pla"):
        list_objects([clash])


@settings(max_examples=60, deadline=None)
@given(
    radii=st.lists(st.floats(10.0, 40.0), min_size=3, max_size=9),
    gaps=st.lists(st.floats(0.2, 1.0), min_size=9, max_size=9),
)
def test_any_star_shaped_outline_loads_and_rays_hit_its_vertices(
    tmp_path_factory: pytest.TempPathFactory, radii: list[float], gaps: list[float]
) -> None:
    n = len(radii)
    steps = np.array(gaps[:n])
    angles = np.cumsum(steps / steps.sum() * 2 * math.pi)
    vertices = np.stack([np.cos(angles), np.sin(angles)], axis=1) * np.array(radii)[:, None]
    path = tmp_path_factory.mktemp("obj") / "poly.json"
    path.write_text(json.dumps({"id": "poly", "material": "PLA", "outline_mm": vertices.tolist(), "wall_mm": 0.5}))
    try:
        obj = load_object_file(path)
    except ConfigError:
        return  # a wall too thick or a sliver: refused with a clear error is fine, anything else is not
    for vertex in obj.outer_mm:
        assert np.allclose(obj.outline_hit(vertex), vertex, atol=1e-6)
