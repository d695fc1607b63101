"""`mesoflow.plan` from Python: the same plan as `mesoflow plan` on the command line (the
planner is one library under both), as objects."""

import json
from pathlib import Path
import subprocess

import pytest

import mesoflow


def test_a_plan_from_python_is_the_command_line_s(repo, cli, tmp_path):
    # The measured model alone (no probe): a probed plan keeps a candidate only where its frame
    # was not slower than the graph's in that run, and on the CPU the far BTF views' frames are a
    # few milliseconds either way, so two runs may keep different ones (this test once compared
    # two such runs and failed on timing alone).
    graph = repo / "graphs" / "plan_verify.json"
    sets = ["btf_view.camera.eye=[0.0,4.0,6.75]"]
    out = tmp_path / "cli" / "planned.json"
    subprocess.run(
        [str(cli), "plan", str(graph), "--render", "btf_view", "--budget", "flip=0.1",
         "--set", sets[0], "-o", str(out), "--quiet", "--probe-budget", "0",
         "--cache-dir", str(tmp_path / "cli-cache")],
        check=True,
    )
    cli_plan = json.loads((out.parent / "planned.plan.json").read_text())
    cli_graph = json.loads(out.read_text())

    p = mesoflow.plan(graph, "btf_view", budget=0.1, set={"btf_view.camera.eye": [0.0, 4.0, 6.75]},
                      probe_budget=0.0, cache_dir=tmp_path / "py-cache")
    assert isinstance(p, mesoflow.Plan)
    assert [d.stage for d in p.decisions] == [d["stage"] for d in cli_plan["decisions"]]
    assert [d.choice for d in p.decisions] == [d["choice"] for d in cli_plan["decisions"]]
    assert p.predicted_error == cli_plan.get("predicted_error")
    assert p.scene == cli_plan["scene"] and p.budget == 0.1
    # The planned graph is the command line's, less the description naming the budget.
    assert p.graph.to_dict()["nodes"] == cli_graph["nodes"]
    # It runs as any graph does, and saves with its plan beside it, named as the CLI names it.
    saved = p.save(tmp_path / "py" / "planned.json")
    assert json.loads((saved.parent / "planned.plan.json").read_text())["decisions"] == p.doc["decisions"]
    assert mesoflow._plan.plan_file(Path("a/torus.planned.json")) == Path("a/torus.plan.json")


def test_an_unknown_render_node_and_a_bad_budget_are_errors(repo):
    graph = repo / "graphs" / "plan_verify.json"
    with pytest.raises(ValueError, match="no node `btf_veiw`"):
        mesoflow.plan(graph, "btf_veiw", budget=0.1)
    with pytest.raises(ValueError, match="budget"):
        mesoflow.plan(graph, "btf_view", budget=-1.0)


def test_a_plan_against_the_truth_from_python_judges_every_candidate(repo, tmp_path):
    # The translucent family's seed 0 at test size (tests/plan_truth.rs's sets): at a lax budget
    # several candidates fit and the fastest of them is planned, as on the command line.
    graph = repo / "graphs" / "family_translucent.json"
    sets = {
        "mesh.segments": [32, 16],
        "ours.camera.resolution": [32, 24],
        "lighting.max_points": 2000,
        "lighting.shadow_resolution": 128,
        "truth.camera.resolution": [32, 24],
    }
    p = mesoflow.plan(graph, "ours", budget=0.5, against="truth", set=sets, probe_share=0.5,
                      cache_dir=tmp_path / "cache")
    assert isinstance(p, mesoflow.TruthPlan)
    assert p.doc["judge"] == "truth" and "medium" in p.judge_why
    families = {c["family"] for c in p.candidates}
    assert families == {"model", "brute force"}
    fits = [c for c in p.candidates if c["within_budget"]]
    chosen = next(c for c in p.candidates if c["candidate"] == p.chosen)
    assert chosen["full_seconds_estimate"] == min(c["full_seconds_estimate"] for c in fits)
    assert p.graph.to_dict()["nodes"]["ours"]["kind"] == chosen["kind"]
    saved = p.save(tmp_path / "planned.json")
    assert json.loads((saved.parent / "planned.plan.json").read_text())["chosen"] == p.chosen
    with pytest.raises(ValueError, match="against="):
        mesoflow.plan(graph, "ours", budget=0.5, against="model")
    # A FLIP budget against the truth: every measured candidate has its FLIP in [0, 1].
    f = mesoflow.plan(graph, "ours", budget=0.5, against="truth", measure="flip", set=sets,
                      probe_share=0.5, cache_dir=tmp_path / "cache")
    assert f.measure == "flip" and f.budget == 0.5 and f.doc["budget"]["ppd"] > 60
    measured = [c for c in f.candidates if "probe_seconds" in c]
    assert measured and all(0.0 <= c["flip"] <= 1.0 for c in measured)
    with pytest.raises(ValueError, match="measure="):
        mesoflow.plan(graph, "ours", budget=0.5, against="truth", measure="psnr")
