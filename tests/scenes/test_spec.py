"""Scene files: parsing, quick variants, shipped scenes and every malformed-file error."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from fpe_harvester.errors import ParameterError
from fpe_harvester.exact import k_di
from fpe_harvester.scenes import Axis, FigureSpec, Optimize, Scene, list_scenes, load_scene

GOOD = """
name = "tiny"
title = "tiny scene"
observables = ["eta", "Vrms"]
rtol = 1e-3
method = "auto"

[system]
a = 0.5
n = 2
N = 3
params = { tau_p = 3.0 }

[axes]
a = [0.5, 1.0]
k = { linspace = [0.0, 1.0, 3], unit = "k_di" }

[options.mc]
dt = 0.01

[[figures]]
name = "eta_vs_k"
x = "k"
y = ["eta", "Vrms"]
series = "a"
refs = [{ vline = "k_di" }, { point = [-0.33, 0.677], label = "paper", panel = "eta" }]

[quick]
rtol = 0.05
axes = { k = { linspace = [0.0, 1.0, 2], unit = "k_di" } }
"""


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_parse_good_scene(tmp_path: Path) -> None:
    sc = load_scene(write(tmp_path, GOOD))
    assert sc.name == "tiny" and sc.observables == ("eta", "Vrms")
    assert sc.system.N == 3 and sc.system.params.tau_p == 3.0
    assert [ax.name for ax in sc.axes] == ["a", "k"]
    assert sc.options["mc"]["dt"] == 0.01
    fig = sc.figures[0]
    assert fig.y == ("eta", "Vrms") and fig.series == "a" and len(fig.refs) == 2
    pts = list(sc.points())
    assert len(pts) == sc.n_points == 6
    # k in units of k_di of each point's (N, a)
    assert pts[2] == {"a": 0.5, "k": pytest.approx(k_di(3, 0.5))}
    assert pts[4]["k"] == pytest.approx(0.5 * k_di(3, 1.0))
    quick = sc.variant(quick=True)
    assert quick.rtol == 0.05 and quick.n_points == 4 and quick.figures == sc.figures
    assert sc.variant(quick=False) is sc


def test_axis_spacings() -> None:
    assert Axis.from_spec("a", {"logspace": [-2, 0, 3]}).values == (0.01, 0.1, 1.0)
    assert Axis.from_spec("N", {"integers": [2, 4]}).values == (2, 3, 4)
    assert Axis.from_spec("tau_p", [1, 2]).values == (1.0, 2.0)
    np.testing.assert_allclose(Axis.from_spec("k", {"linspace": [0, -0.03, 4]}).values,
                               [0, -0.01, -0.02, -0.03])


def test_python_objects() -> None:
    sc = Scene("py", axes=(Axis("k", (0.0, -0.1)),), observables="eta",
               system=load_scene("fig4_eta_vs_k_harmonic").system,
               figures=(FigureSpec("f", x="k", y="eta"),), optimize=None)
    assert sc.observables == ("eta",) and sc.figures[0].y == ("eta",)
    with pytest.raises(ParameterError, match="observables must be one of .*'eta'.*got 'power'"):
        Scene("py", observables=("power",))
    with pytest.raises(ParameterError, match="optimize.over: 'k' is also a sweep axis"):
        Scene("py", axes=(Axis("k", (0.0,)),), optimize=Optimize(over="k"))


def test_shipped_scenes_load() -> None:
    names = list_scenes()
    for expected in ("fig1_eta_vs_n", "fig2_eta_vs_k_n1_ring", "fig3_eta_vs_k_n3_ring",
                     "fig4_eta_vs_k_harmonic", "fig5_optimum_vs_N", "fig6_eta_vs_k_several_a", "kdi_map"):
        assert expected in names
    for name in names:
        sc = load_scene(name)
        assert sc.name == name and sc.figures
        assert sc.quick is not None and sc.quick.n_points <= sc.n_points
        for p in sc.variant(True).points():
            sc.harvester(p)


BAD = [
    ("name = 'x'\nobservables = [", "is not valid TOML"),
    ("name = 'x'\ncolour = 'red'", "unknown key 'colour'; valid keys: name, title"),
    ("name = 'x'\nobservables = ['eta', 'power']", "observables must be one of 'eta', 'V2'.*got 'power'"),
    ("name = 'x'\nobservables = 3", "observables: invalid value 3"),
    ("name = 'x'\nmethod = 'rk4'", "method must be one of 'auto', 'exact', 'fpe', 'mc'; got 'rk4'"),
    ("name = 'x'\nrtol = 2.0", r"rtol must be in \(0, 1\), got 2.0"),
    ("name = 'x'\nrtol = 'tight'", "rtol must be a real number"),
    ("name = 'x'\n[system]\nb = 1", "system: unknown key 'b'; valid keys: a, n, N, k, k4, k3, params"),
    ("name = 'x'\n[system]\na = -1.0", r"a must be in \(0, inf\), got -1.0"),
    ("name = 'x'\n[system]\nN = 2.5", r"N must be an integer in \[1, inf\], got 2.5"),
    ("name = 'x'\n[system]\nparams = { mass = 2 }", "system.params: unknown key 'mass'; valid keys: m, gamma"),
    ("name = 'x'\n[system]\nparams = { tau_p = 0 }", r"tau_p must be in \(0, inf\), got 0"),
    ("name = 'x'\n[axes]\nz = [1]", "axes: unknown axis 'z'; valid axes: a, n, N, k"),
    ("name = 'x'\n[axes]\nk = { linspace = [0, 1, 3], values = [1] }", "give exactly one of values, linspace"),
    ("name = 'x'\n[axes]\nk = { linspace = [0, 1] }", r"axes.k.linspace: invalid value \[0, 1\].*\[start, stop, num\]"),
    ("name = 'x'\n[axes]\nk = { linspace = [0, 1, 0] }", r"axes.k.linspace num must be an integer in \[1, inf\]"),
    ("name = 'x'\n[axes]\nk = []", "axes.k: invalid value"),
    ("name = 'x'\n[axes]\nk = ['a']", "axes.k value must be a real number"),
    ("name = 'x'\n[axes]\nN = [1.5]", "axes.N value must be an integer"),
    ("name = 'x'\n[axes]\na = { values = [1], unit = 'k_di' }", "axes.a.unit: unit 'k_di' is valid only for axis 'k'"),
    ("name = 'x'\n[axes]\nk = { values = [1], unit = 'm' }", "axes.k.unit must be one of '', 'k_di'; got 'm'"),
    ("name = 'x'\n[axes]\nk = { values = [1], step = 2 }", "axes.k: unknown key 'step'"),
    ("name = 'x'\naxes = 3", "axes: invalid value 3"),
    ("name = 'x'\n[axes]\nk=[0]\n[optimize]\nover = 'k'", "optimize.over: 'k' is also a sweep axis"),
    ("name = 'x'\n[optimize]\nover = 'N'", "optimize.over must be one of"),
    ("name = 'x'\n[optimize]\nmaximize = 'eta'", "optimize: missing required key 'over'"),
    ("name = 'x'\n[optimize]\nover = 'k'\nmaximize = 'cost'", "optimize.maximize must be one of 'eta'"),
    ("name = 'x'\n[optimize]\nover = 'a'\nbounds = ['k_di', 1]", "optimize.bounds: invalid value 'k_di'"),
    ("name = 'x'\n[optimize]\nover = 'k'\nbounds = [1]", r"optimize.bounds: invalid value \[1\]"),
    ("name = 'x'\n[optimize]\nover = 'k'\npoints = 2", r"optimize.points must be an integer in \[3, inf\]"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'a'", "figures.f: 'a' is not a sweep axis"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'", r"figures\[0\]: missing required key 'x'"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\ny = ['power']", "figures.f.y must be one of"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\ncolor = 1", r"figures\[0\]: unknown key 'color'"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nlogx = 'yes'", "figures.f.logx: invalid value 'yes'"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nrefs = [{vline = 1, hline = 2}]",
     r"figures\[0\].refs\[0\]: give exactly one of vline, hline, point"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nrefs = [{point = 1}]",
     r"figures\[0\].refs\[0\].point: invalid value 1"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nrefs = [{hline = 'top'}]",
     "refs.hline y must be a real number"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nxnorm = 'a'", "xnorm must be one of"),
    ("name = 'x'\nfigures = 3", "figures: invalid value 3"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nkind = 'map'", "kind = 'map' needs series"),
    ("name = 'x'\n[axes]\nk=[0]\n[[figures]]\nname = 'f'\nx = 'k'\nkind = 'bars'", "figures.f.kind must be one of"),
    ("name = 'x'\n[options.rk4]\ndt = 1", "options: unknown key 'rk4'; valid keys: exact, fpe, mc"),
    ("name = 'x'\n[options]\nmc = 3", "options.mc: invalid value 3"),
    ("name = 'x'\noutputs = ['pdf']", "outputs must be one of 'table', 'csv', 'json'; got 'pdf'"),
    ("name = 'x'\n[quick]\npoints = 3", "quick: unknown key 'points'; valid keys: rtol, axes"),
    ("name = 'x'\n[axes]\nk=[0]\n[quick]\naxes = { a = [1] }", "quick.axes: unknown key 'a'; valid keys: k"),
    ("name = 'x'\n[quick]\nrtol = -1", r"rtol must be in \(0, 1\)"),
    ("name = 'bad name'", "name: invalid value 'bad name'"),
    ("", "system: missing required table; a scene states its base harvester"),
    ("name = 'x'\n[system]\n", "system: the table is empty"),
    ("name = 'x'\n[system]\nn = 3\n[options.mc]\nfoo = 1", "options.mc: invalid option for method 'mc': no option 'foo'"),
    ("name = 'x'\n[system]\nn = 3\n[options.fpe]\ntol = 0.5", r"options.fpe: tol must be in \(0, 0.1\]"),
]


@pytest.mark.parametrize("text, match", BAD)
def test_malformed_scene_files(tmp_path: Path, text: str, match: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ParameterError, match=match) as info:
        load_scene(path)
    assert str(path) in str(info.value)


def test_missing_file_and_unknown_name(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="cannot be read"):
        load_scene(tmp_path / "nope.toml")
    with pytest.raises(ParameterError, match="neither a file nor a shipped scene; shipped scenes: fig1"):
        load_scene("fig9_nothing")


def test_name_defaults_to_file_stem(tmp_path: Path) -> None:
    sc = load_scene(write(tmp_path, "observables = ['eta']\n[system]\nn = 2", name="my_study.toml"))
    assert sc.name == "my_study" and sc.n_points == 1
