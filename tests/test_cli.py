"""The command line: choosing sites and recipes, composition errors, plugins, bad input."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys

from tests.conftest import ROOT


def test_unknown_site_and_recipe_are_one_line_errors_listing_what_exists(project):
    r = project.run("site=nowhere", "recipe=chain")
    assert r.rc == 2
    assert r.err.strip().count("\n") == 0, r.err
    assert "unknown site 'nowhere'" in r.err and "available: t" in r.err
    r = project.run("site=t", "recipe=nope")
    assert r.rc == 2 and "unknown recipe 'nope'" in r.err and "chain" in r.err
    r = project.run("site=", "recipe=chain")
    assert r.rc == 2 and "no site given" in r.err


def test_corrupt_yaml_names_the_file_and_line(project):
    (project.conf / "site" / "t.yaml").write_text("name: t\ninputs: [unclosed\n")
    r = project.run("site=t", "recipe=chain")
    assert r.rc == 2
    assert re.search(r"site/t\.yaml: line \d+", r.err), r.err
    assert r.err.strip().count("\n") == 0


def test_cfg_job_prints_the_composed_config_without_running(project):
    r = project.run("site=t", "recipe=chain", "steps.scale.factor=9", "--cfg", "job")
    assert r.rc == 0, r.text
    assert "factor: 9" in r.out and "name: chain" in r.out
    assert not project.ws.exists() or not (project.ws / "01_make").exists()


def test_parameter_typo_and_wrong_type_fail_at_composition(project):
    r = project.run("site=t", "recipe=chain", "steps.scale.factr=5")
    assert r.rc != 0 and "factr" in r.err and "ScaleParams" in r.err
    r = project.run("site=t", "recipe=chain", "steps.scale.factor=lots")
    assert r.rc != 0 and "steps.scale.factor" in r.err
    assert not (project.ws / "01_make").exists()


def test_command_line_step_params_beat_the_recipes_fixed_params(project):
    """A recipe fixes make.value=5; steps.make.value=7 on the command line wins; without it the recipe's
    value holds (not the plugin's default 1)."""
    project.recipe("fixed", ["{id: make, uses: step/make, params: {value: 5}}", "{id: double, uses: step/double}"])
    r = project.run("site=t", "recipe=fixed")
    assert r.rc == 0, r.err
    assert (project.ws / "02_double" / "double.txt").read_text().strip() == "10"
    r = project.run("site=t", "recipe=fixed", "steps.make.value=7")
    assert r.rc == 0, r.err
    assert (project.ws / "02_double" / "double.txt").read_text().strip() == "14"
    r = project.run("status", "site=t", "recipe=fixed", "steps.make.value=9")  # status reads the same way
    assert r.rc == 0 and "value 7 -> 9" in r.out


def test_recipe_step_params_are_checked_against_the_plugin(project):
    project.recipe("badparam", ["{id: make, uses: step/make, params: {valeu: 3}}"])
    r = project.run("site=t", "recipe=badparam")
    assert r.rc == 2
    assert "plugin step/make has no parameter 'valeu'" in r.err and "value" in r.err


def test_unknown_plugin_in_recipe(project):
    project.recipe("badplugin", ["{id: x, uses: step/does_not_exist}"])
    r = project.run("site=t", "recipe=badplugin")
    assert r.rc == 2
    assert "no step plugin named 'does_not_exist'" in r.err and "make" in r.err


def test_missing_site_input_file(project):
    project.site("s", f"name: t\ninputs:\n  seed: {project.tmp / 'missing.txt'}\n")
    project.recipe("fromseed", ["{id: read, uses: step/read_seed}"])
    r = project.run("site=s", "recipe=fromseed")
    assert r.rc == 2 and "missing.txt does not exist" in r.err


def test_site_input_left_for_the_user(project):
    project.site("m", "name: m\ninputs:\n  seed: ???\n")
    project.recipe("fromseed", ["{id: read, uses: step/read_seed}"])
    r = project.run("site=m", "recipe=fromseed")
    assert r.rc == 2
    assert "site 'm' needs input 'seed'" in r.err and "site.inputs.seed=" in r.err and "conf/local/m.yaml" in r.err
    seed = project.tmp / "seed.txt"
    seed.write_text("3\n")
    (project.conf / "local").mkdir()
    (project.conf / "local" / "m.yaml").write_text(f"# @package _global_\nsite:\n  inputs:\n    seed: {seed}\n")
    r = project.run("site=m", "recipe=fromseed")
    assert r.rc == 0, r.text
    assert (project.out / "m" / "01_read" / "data.txt").read_text() == "3\n"


def test_site_input_not_in_the_site_file_is_added_from_the_command_line(project):
    # a site file without an 'inputs' section: the input is still given with a plain override
    project.site("bare", "name: bare\n")
    project.recipe("fromseed", ["{id: read, uses: step/read_seed}"])
    seed = project.tmp / "seed.txt"
    seed.write_text("5\n")
    r = project.run("site=bare", "recipe=fromseed", f"site.inputs.seed={seed}")
    assert r.rc == 0, r.text
    assert (project.out / "bare" / "01_read" / "data.txt").read_text() == "5\n"
    # other site keys stay strict: a typo is refused, not silently added
    r = project.run("site=bare", "recipe=fromseed", f"site.inputs.seed={seed}", "site.sede=3")
    assert r.rc == 2 and "sede" in r.err


def test_unwritable_outputs_folder(project):
    blocker = project.tmp / "a_file"
    blocker.write_text("")
    r = project.run("site=t", "recipe=chain", f"engine.outputs_dir={blocker}/sub", outputs=False)
    assert r.rc == 2 and "cannot write to the outputs folder" in r.err and "engine.outputs_dir" in r.err


def test_plugins_command_lists_distributions_and_versions(project):
    r = project.run("plugins")
    assert r.rc == 0, r.text
    assert re.search(r"executor\s+local\s+0\.1\.0\s+twinkit-builtins", r.out), r.out
    assert re.search(r"step\s+scale\s+0\s+tests\.support\.engine_plugins", r.out), r.out


def test_plugin_selection_by_environment(project):
    r = project.run("plugins", env=project.env(TWINKIT_PLUGINS="", TWINKIT_PLUGIN_MODULES=""))
    assert r.rc == 0 and "no plugins loaded" in r.out


def test_duplicate_plugin_name_is_an_error(project):
    env = project.env(TWINKIT_PLUGIN_MODULES="tests.support.engine_plugins,tests.support.bad_plugins")
    r = project.run("plugins", env=env)
    assert r.rc == 2 and "step plugin 'make' is registered twice" in r.err


def test_misspelled_hook_fails_loudly(project):
    r = project.run("plugins", env=project.env(TWINKIT_PLUGIN_MODULES="tests.support.misspelled_hook"))
    assert r.rc == 2 and "twinkit_register_step" in r.err


def test_example_plugin_installed_and_selected_from_the_command_line(project, tmp_path):
    target = tmp_path / "site-packages"
    # built from a copy: pip's build/ and egg-info would otherwise stay in examples/, where the next session's
    # entry-point scan finds the plugin (its tests put that folder on sys.path)
    src = shutil.copytree(ROOT / "examples" / "twinkit-example-plugin", tmp_path / "example-src",
                          ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    pip = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--target",
         str(target), str(src)],
        # --no-deps: its dependencies (twinkit[mesh], numpy) are those of this environment; pip would pull twinkit from PyPI
        capture_output=True, text=True, timeout=300)
    assert pip.returncode == 0, pip.stderr
    env = project.env(TWINKIT_PLUGINS="builtins,example",
                      PYTHONPATH=f"{target}:{ROOT}")
    r = project.run("plugins", env=env)
    assert re.search(r"exporter\s+xyz\s+1\.0\.0\s+twinkit-example-plugin", r.out), r.text
    project.recipe("export", ["{id: mesh, uses: step/make_ply}", "{id: export, uses: exporter}"],
                   extra="defaults:\n  - /exporter: xyz\n  - _self_\n")
    r = project.run("site=t", "recipe=export", "exporter=xyz", "exporter.decimals=1", env=env)
    assert r.rc == 0, r.text
    assert (project.ws / "02_export" / "points.xyz").read_text().splitlines() == ["0.0 0.0 0.0", "1.0 0.0 0.0",
                                                                                  "0.0 2.0 0.0"]
    # its report section (hook twinkit_register_report_sections) finds its own step's output
    report = (sorted((project.ws / "runs").iterdir())[-1] / "report" / "report.html").read_text()
    sec = report.split("<section id=\"xyz_points\">", 1)[1].split("</section>", 1)[0]
    assert "<h2>Exported points</h2>" in sec and "02_export" in sec and ">3</td>" in sec and "points.xyz" in sec
    r = project.run("site=t", "recipe=export", "exporter.decimls=1", env=env)
    assert r.rc != 0 and "decimls" in r.err


def test_writing_a_plugin_doc_matches_the_tested_example():
    doc = (ROOT / "docs" / "writing-a-plugin.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", doc, re.S)
    src = (ROOT / "examples" / "twinkit-example-plugin" / "twinkit_example" / "plugin.py").read_text()
    assert src in blocks, "docs/writing-a-plugin.md must show examples/.../plugin.py verbatim"
    toml = re.findall(r"```toml\n(.*?)```", doc, re.S)
    assert (ROOT / "examples" / "twinkit-example-plugin" / "pyproject.toml").read_text() in toml


def test_help_is_fast_and_imports_nothing_heavy():
    code = ("import sys; from twinkit.cli import main; main(['--help']); "
            "heavy = [m for m in ('open3d', 'torch', 'bpy', 'pycolmap', 'hydra') if m in sys.modules]; "
            "print('HEAVY', heavy)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert "HEAVY []" in p.stdout, p.stdout + p.stderr


def test_unknown_plugin_on_the_command_line(project):
    r = project.run("site=t", "recipe=chain", "executor=nope")
    assert r.rc == 2
    assert "no executor plugin named 'nope' (available: local)" in r.err
    assert r.err.strip().count("\n") == 0, r.err


def test_plugins_command_prints_a_plugins_parameters(project):
    r = project.run("plugins", "step/scale")
    assert r.rc == 0, r.text
    lines = r.out.splitlines()
    assert lines[0].startswith("step/scale") and "Multiply by a factor." in lines[0]
    assert re.match(r"\s+parameter\s+type\s+range\s+default$", lines[1]), r.out
    assert re.search(r"^\s+factor\s+int\s+any number\s+3$", r.out, re.M), r.out
    assert re.search(r"^\s+degrade_below\s+int\s+>= 0\s+0$", r.out, re.M), r.out
    assert re.search(r"^\s+a result below this says it is degraded \(ctx\.degraded\)$", r.out, re.M), r.out
    r = project.run("plugins", "step/double")
    assert r.rc == 0 and "no parameters" in r.out, r.text


def test_plugins_command_names_what_exists_for_an_unknown_plugin(project):
    r = project.run("plugins", "step/nope")
    assert r.rc == 2 and r.err.strip().count("\n") == 0, r.text
    assert "no plugin 'step/nope'" in r.err and "step/scale" in r.err and "executor/local" in r.err
