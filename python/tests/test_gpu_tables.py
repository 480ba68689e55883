"""EnvironmentLight.gpu_tables(): the flat GPU tables of docs/gpu-tables.md as numpy
arrays, checked for shapes and dtypes, against the map, against the documented
layout, and against the file `envlight export` writes."""

import pathlib
import re
import subprocess

import numpy as np
import pytest

import envlight

CDF_ONE = 2**32 - 1

# The Rust source of the parameter block's layout: the one definition of its words.
RUST_GPU_MOD = pathlib.Path(__file__).resolve().parents[2] / "crates" / "envlight" / "src" / "gpu" / "mod.rs"


def rust_param_words():
    """``envlight::gpu::param``'s constants (name → word), read from the Rust source."""
    if not RUST_GPU_MOD.is_file():
        pytest.skip(f"the Rust source is not here ({RUST_GPU_MOD})", allow_module_level=True)
    text = RUST_GPU_MOD.read_text(encoding="utf-8")
    block = re.search(r"pub mod param \{(.*?)\n\}", text, re.S)
    assert block, "no `pub mod param` in gpu/mod.rs"
    words = {name: int(value) for name, value in re.findall(r"pub const (\w+): usize = (\d+);", block.group(1))}
    assert words, "no constants in `pub mod param`"
    total = re.search(r"pub const PARAMS_WORDS: usize = (\d+);", text)
    assert total, "no PARAMS_WORDS in gpu/mod.rs"
    words["PARAMS_WORDS"] = int(total.group(1))
    return words


# Word indices of the parameter block (docs/gpu-tables.md), from the Rust constants.
PARAM = rust_param_words()
VERSION, SAMPLER, DENSITY, RADIANCE_FORMAT = (PARAM[k] for k in ("VERSION", "SAMPLER", "DENSITY", "RADIANCE_FORMAT"))
IMAGE_W, IMAGE_H, TABLE_W, TABLE_H, SCALE = (
    PARAM[k] for k in ("IMAGE_WIDTH", "IMAGE_HEIGHT", "TABLE_WIDTH", "TABLE_HEIGHT", "SCALE")
)
OFFSETS = {
    name: PARAM[name.upper()]
    for name in (
        "marginal_cdf", "marginal_guide", "conditional_cdf", "conditional_guide",
        "alias_slots", "alias_func", "bilinear_values",
    )
}
TABLES_WORDS = PARAM["TABLES_WORDS"]


def test_the_drjit_port_reads_the_rust_words():
    """``_drjit_tables._W`` (the Dr.Jit port's words) is the Rust layout."""
    pytest.importorskip("drjit")
    from envlight import _drjit_tables

    for name, word in _drjit_tables._W.items():
        assert PARAM.get(name.upper()) == word, name
    assert _drjit_tables._PARAMS_WORDS == PARAM["PARAMS_WORDS"]
    assert (PARAM["LIGHT_TO_WORLD"], PARAM["WORLD_TO_LIGHT"]) == (
        _drjit_tables._LIGHT_TO_WORLD, _drjit_tables._WORLD_TO_LIGHT,
    )


def small_map(h=16, w=32):
    """A smooth sky, a bright spot and a few black texels."""
    v = (np.arange(h) + 0.5) / h
    rgb = np.empty((h, w, 3), np.float32)
    rgb[...] = (0.2 + 0.8 * np.cos(np.pi * v / 2))[:, None, None] * np.array([0.5, 0.7, 1.0], np.float32)
    rgb[3, 20, :] = 300.0
    rgb[::5, ::7, :] = 0.0
    return rgb


def padded(n):
    return -(-n // 4) * 4


def check_tables_buffer(t):
    """Every sampling section sits in "tables" at its offset in params."""
    params, tables = t["params"], t["tables"]
    assert tables.dtype == np.uint32 and tables.ndim == 1
    assert len(tables) == params[TABLES_WORDS]
    end = 0
    for name, word in OFFSETS.items():
        if name not in t:
            assert params[word] == 0, name
            continue
        flat = t[name].reshape(-1).view(np.uint32)
        at = int(params[word])
        assert at == end, name
        assert np.array_equal(tables[at : at + len(flat)], flat), name
        end = at + padded(len(flat))
    assert end == len(tables)


def test_shapes_dtypes_and_the_map():
    rgb = small_map()
    light = envlight.EnvironmentLight.from_array(rgb, scale=2.0, density="piecewise-constant")
    t = light.gpu_tables()
    assert t["version"] == 1
    assert set(t) == {
        "version", "params", "tables", "marginal_cdf", "marginal_guide",
        "conditional_cdf", "conditional_guide", "radiance",
    }
    p = t["params"]
    assert p.dtype == np.uint32 and p.shape == (64,)
    assert p[VERSION] == 1 and p[SAMPLER] == 0 and p[DENSITY] == 0 and p[RADIANCE_FORMAT] == 0
    assert (p[IMAGE_W], p[IMAGE_H], p[TABLE_W], p[TABLE_H]) == (32, 16, 32, 16)
    assert p[SCALE:SCALE + 1].view(np.float32)[0] == 2.0
    assert t["marginal_cdf"].dtype == np.uint32 and t["marginal_cdf"].shape == (17,)
    assert t["marginal_cdf"][0] == 0 and t["marginal_cdf"][-1] == CDF_ONE
    assert t["conditional_cdf"].shape == (16, 33)
    assert (t["conditional_cdf"][:, 0] == 0).all() and (t["conditional_cdf"][:, -1] == CDF_ONE).all()
    assert t["conditional_guide"].dtype == np.uint32 and t["conditional_guide"].shape[0] == 16
    assert t["marginal_guide"].ndim == 1
    assert (t["conditional_guide"] < 32).all() and (t["marginal_guide"] < 16).all()
    # The radiance is the map, unscaled.
    assert t["radiance"].dtype == np.float32 and t["radiance"].shape == (16, 32, 3)
    assert np.array_equal(t["radiance"], rgb)
    check_tables_buffer(t)


def test_alias_bilinear_and_reduced_tables():
    rgb = small_map()
    t = envlight.EnvironmentLight.from_array(rgb, sampler="alias").gpu_tables()
    assert t["params"][SAMPLER] == 1
    assert "marginal_cdf" not in t and "bilinear_values" not in t
    assert t["alias_slots"].dtype == np.uint32 and t["alias_slots"].shape == (512, 2)
    assert (t["alias_slots"][:, 1] < 512).all()
    thresholds = t["alias_slots"][:, 0].copy().view(np.float32)
    assert ((thresholds >= 0) & (thresholds <= 1)).all()
    assert t["alias_func"].dtype == np.float32 and t["alias_func"].shape == (16, 32)
    check_tables_buffer(t)

    t = envlight.EnvironmentLight.from_array(rgb, density="piecewise-bilinear").gpu_tables()
    p = t["params"]
    assert p[DENSITY] == 1 and (p[TABLE_W], p[TABLE_H]) == (33, 17)
    assert t["bilinear_values"].dtype == np.float32 and t["bilinear_values"].shape == (18, 34)
    assert t["marginal_cdf"].shape == (18,) and t["conditional_cdf"].shape == (17, 34)
    check_tables_buffer(t)

    t = envlight.EnvironmentLight.from_array(rgb, table_width=8).gpu_tables()
    p = t["params"]
    assert (p[IMAGE_W], p[IMAGE_H], p[TABLE_W], p[TABLE_H]) == (32, 16, 8, 4)
    assert t["conditional_cdf"].shape == (4, 9)
    assert t["radiance"].shape == (16, 32, 3)
    check_tables_buffer(t)


def test_f16_radiance():
    rgb = small_map()
    light = envlight.EnvironmentLight.from_array(rgb)
    t = light.gpu_tables(radiance="f16")
    assert t["params"][RADIANCE_FORMAT] == 1
    r = t["radiance"]
    assert r.dtype == np.float16 and r.shape == (16, 32, 4)
    assert (r[..., 3] == 0).all()
    # Rounded to nearest even, as numpy rounds.
    assert np.array_equal(r[..., :3], rgb.astype(np.float16))
    assert np.array_equal(t["tables"], light.gpu_tables()["tables"])


def test_errors():
    rgb = small_map()
    with pytest.raises(ValueError, match="not ported to the GPU"):
        envlight.EnvironmentLight.from_array(rgb, sampler="hierarchical").gpu_tables()
    light = envlight.EnvironmentLight.from_array(rgb)
    with pytest.raises(ValueError, match="f32"):
        light.gpu_tables(radiance="f64")
    rgb[2, 5, 0] = 1e5
    bright = envlight.EnvironmentLight.from_array(rgb)
    with pytest.raises(ValueError, match=r"\(5, 2\).*65504"):
        bright.gpu_tables(radiance="f16")
    assert bright.gpu_tables()["radiance"][2, 5, 0] == np.float32(1e5)



def read_sections(data):
    """The sections of a GPU tables file, read by the documented layout."""
    assert data[:8] == b"ENVLGPU\0"
    version, count = np.frombuffer(data, "<u4", 2, 8)
    assert version == 1
    out = {}
    for k in range(count):
        at = 16 + 32 * k
        ident, element = np.frombuffer(data, "<u4", 2, at)
        offset, length, elements = np.frombuffer(data, "<u8", 3, at + 8)
        assert offset % 16 == 0
        dtype = {0: "<u4", 1: "<f4", 2: "<f2"}[int(element)]
        out[int(ident)] = (int(offset), np.frombuffer(data, dtype, int(elements), int(offset)))
    return out


def test_equal_to_the_file_envlight_export_writes(tmp_path, envlight_cli):
    cli = envlight_cli
    rgb = small_map()
    h, w, _ = rgb.shape
    path = tmp_path / "map.pfm"
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())
    out = tmp_path / "map.envgpu"
    try:
        subprocess.run([cli, "export", str(path), "--rotate", "30", "-o", str(out)], check=True, capture_output=True)
    except subprocess.CalledProcessError as e:
        if b"unrecognized subcommand" in e.stderr:
            pytest.skip("the envlight binary predates `export`")
        raise
    sections = read_sections(out.read_bytes())
    t = envlight.EnvironmentLight(path, rotate=30.0).gpu_tables()
    assert np.array_equal(sections[1][1], t["params"])
    assert np.array_equal(sections[9][1].reshape(h, w, 3), t["radiance"])
    first = min(off for ident, (off, _) in sections.items() if 2 <= ident <= 8)
    data = out.read_bytes()
    assert np.array_equal(np.frombuffer(data, "<u4", len(t["tables"]), first), t["tables"])
