"""The studio (`mesoflow serve`) in a real browser: Debian's Chromium driven by Selenium through
Debian's chromedriver (no browser is downloaded at run time).

Run by the README's test command (scripts/test). Without Chromium the tests skip, unless
MESOFLOW_REQUIRE_BROWSER=1 (CI sets it), when they fail. The screenshots in the README are made
here, into MESOFLOW_STUDIO_SCREENSHOTS (default target/studio-screenshots).
"""

import json
import os
import re
import shutil
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("MESOFLOW_BIN", str(ROOT / "target" / "release" / "mesoflow"))
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
# `scripts/test --bare` hides the optional parts to prove that the run is green without them.
HIDDEN = os.environ.get("MESOFLOW_HIDE_OPTIONAL") == "1"
REQUIRED = os.environ.get("MESOFLOW_REQUIRE_BROWSER") == "1"
SHOTS = Path(os.environ.get("MESOFLOW_STUDIO_SCREENSHOTS", ROOT / "target" / "studio-screenshots"))


def _browser_missing():
    if HIDDEN:
        return "the optional parts are hidden (MESOFLOW_HIDE_OPTIONAL=1)"
    if not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)):
        return "Chromium and chromedriver are not installed (Debian: chromium chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed"
    return None


MISSING = _browser_missing()
if MISSING and REQUIRED:
    raise RuntimeError(f"MESOFLOW_REQUIRE_BROWSER=1 but {MISSING}")


class Studio:
    """`mesoflow serve` on a copy of a graph, in a temporary folder of its own."""

    def __init__(self, tmp: Path, graph: Path):
        self.dir = tmp
        self.graph = tmp / graph.name
        shutil.copy(graph, self.graph)
        # The graph files it uses as nodes go with it (graphs/mdf_render.json's `tile`).
        for node in json.loads(graph.read_text()).get("nodes", {}).values():
            if node.get("kind") == "graph":
                shutil.copy(graph.parent / node["params"]["path"], tmp / node["params"]["path"])
        # Run from the graph's folder with relative paths, as a user would (the page shows them).
        self.proc = subprocess.Popen(
            [BIN, "serve", graph.name, "--port", "0", "--out-dir", "out", "--cache-dir", "cache",
             "--interval-ms", "200"],
            cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        line = ""
        deadline = time.time() + 60
        while "http://" not in line:
            line = self.proc.stdout.readline()
            if not line and self.proc.poll() is not None or time.time() > deadline:
                raise RuntimeError("mesoflow serve did not start")
        self.url = re.search(r"http://\S+", line).group(0)
        self.base, self.token = self.url.split("/?token=")

    def get(self, path, token=True):
        sep = "&" if "?" in path else "?"
        full = self.base + path + (f"{sep}token={self.token}" if token else "")
        try:
            with urllib.request.urlopen(full, timeout=30) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as e:
            return e.code, e.read()

    def report(self):
        return json.loads((self.dir / "out" / "report.json").read_text())

    def close(self):
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


@pytest.fixture
def studio_of(tmp_path):
    made = []

    def start(graph):
        d = tmp_path / f"studio{len(made)}"
        d.mkdir()
        made.append(Studio(d, graph))
        return made[-1]

    yield start
    for s in made:
        s.close()


@pytest.fixture
def browser():
    # Every test that drives the page asks for this fixture, so none can forget to skip.
    if MISSING:
        pytest.skip(MISSING)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ["--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1500,900",
              "--disable-dev-shm-usage", "--no-first-run", "--disable-background-networking",
              "--disable-component-update", "--disable-sync"]:
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    d = webdriver.Chrome(service=Service(DRIVER), options=opts)
    d.set_script_timeout(60)
    yield d
    # Any script error in the page fails the test that caused it.
    # (Refused edits are answered 422 on purpose; Chromium logs those as network errors.)
    errors = [e for e in d.get_log("browser") if e["level"] == "SEVERE" and e.get("source") != "network"]
    d.quit()
    assert not errors, errors


def wait(browser, script, timeout=120, what=""):
    deadline = time.time() + timeout
    while time.time() < deadline:
        v = browser.execute_script(script)
        if v:
            return v
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what or script}")


def wait_loaded(browser, timeout=600):
    """Waits until the studio shows the finished run of the graph it loaded."""
    return wait(browser, """const s = window.studio;
        return s.state && !s.state.running && s.state.report ? true : null;""", timeout, "the first run")


def edit_and_wait(browser, param, value, timeout=600):
    """Types a parameter's new value, waits for the server to accept it and for the run of that
    revision to finish; returns that run (its `reran` list)."""
    before = browser.execute_script("return window.studio.editRevision || 0")
    set_field(browser, param, value)
    rev = wait(browser, f"return (window.studio.editRevision || 0) > {before} && window.studio.editRevision",
               30, f"the server to accept {param}")
    return wait(browser, f"""const r = window.studio.lastRun;
        return r && !r.cancelled && r.revision >= {rev} ? r : null;""", timeout, f"the run after {param}")


def descendants(graph: dict, start: str):
    nodes = graph["nodes"]
    out = {start}
    changed = True
    while changed:
        changed = False
        for nid, d in nodes.items():
            if nid not in out and any(v.split(".")[0] in out for v in d.get("inputs", {}).values()):
                out.add(nid)
                changed = True
    return out


def click(browser, selector):
    """Clicks an element, looking it up again if the page rebuilt it meanwhile."""
    from selenium.common.exceptions import StaleElementReferenceException

    for _ in range(10):
        try:
            browser.find_element("css selector", selector).click()
            return
        except StaleElementReferenceException:
            time.sleep(0.2)
    raise AssertionError(f"could not click {selector}")


def select(browser, node_id, tab):
    click(browser, f'g.node[data-id="{node_id}"]')
    click(browser, f'#tabs button[data-tab="{tab}"]')


def set_field(browser, param, value):
    """Types a value into a parameter's number box and leaves it, as a user does."""
    from selenium.common.exceptions import StaleElementReferenceException
    from selenium.webdriver.common.keys import Keys

    for _ in range(5):
        try:
            box = browser.find_element("css selector", f'#tab-node input[type=number][data-param="{param}"]')
            box.send_keys(Keys.CONTROL, "a")
            box.send_keys(str(value), Keys.TAB)
            return
        except StaleElementReferenceException:
            time.sleep(0.2)  # the form was being rebuilt (a run or an edit arrived)
    raise AssertionError(f"could not type into {param}")


def canvas_data(browser, selector="#preview-canvas"):
    return wait(browser, f"""const c = document.querySelector('{selector}');
        return c && c.width > 0 && +c.dataset.draws > 0 ? c.toDataURL() : null;""", 60, selector)


def shot(browser, name):
    SHOTS.mkdir(parents=True, exist_ok=True)
    browser.save_screenshot(str(SHOTS / name))


# ---- tests --------------------------------------------------------------------------------

def test_the_token_is_required(studio_of):
    s = studio_of(ROOT / "graphs" / "quickstart.json")
    for path in ["/", "/api/state", "/api/events", "/api/file?path=report.json"]:
        code, body = s.get(path, token=False)
        assert code == 401, path
        assert b"token" in body
    code, _ = s.get("/api/state?token=" + "0" * len(s.token), token=False)
    assert code == 401
    code, body = s.get("/api/state")
    assert code == 200 and json.loads(body)["nodes"]


def test_a_path_outside_the_allowed_folders_is_refused(studio_of, tmp_path):
    s = studio_of(ROOT / "graphs" / "quickstart.json")
    secret = tmp_path / "secret.txt"
    secret.write_text("no")
    for p in ["../../secret.txt", str(secret), "/etc/passwd", "../" * 12 + "etc/passwd"]:
        code, body = s.get("/api/file?path=" + urllib.request.quote(p))
        assert code == 403, (p, body)
    # Inside the output folder it is served (the run writes report.json there).
    deadline = time.time() + 60
    while not (s.dir / "out" / "report.json").exists() and time.time() < deadline:
        time.sleep(0.2)
    code, body = s.get("/api/file?path=report.json")
    assert code == 200 and json.loads(body)["ok"]


def test_a_change_reruns_exactly_its_dependants_and_the_preview_changes(studio_of, browser):
    s = studio_of(ROOT / "graphs" / "quickstart.json")
    graph = json.loads(s.graph.read_text())
    browser.get(s.url)
    wait_loaded(browser)
    select(browser, "surface", "preview")
    browser.find_element("css selector", '.preview-tabs button[data-port="preview"]').click()
    wait(browser, "return document.querySelector('#preview-body')?.dataset.view === 'image'")
    before = canvas_data(browser)
    shot(browser, "studio-quickstart.png")

    browser.find_element("css selector", '#tabs button[data-tab="node"]').click()
    run = edit_and_wait(browser, "size", 128)
    assert set(run["reran"]) == descendants(graph, "surface")
    report = s.report()
    computed = {n["id"] for n in report["nodes"] if n["status"] == "computed"}
    assert computed == descendants(graph, "surface")
    browser.find_element("css selector", '#tabs button[data-tab="preview"]').click()
    after = wait(browser, f"""const c = document.querySelector('#preview-canvas');
        return c && c.width === 128 ? c.toDataURL() : null;""", 60, "the 128² preview")
    assert after != before

    # A parameter of one writer: that writer alone re-runs, everything else is a memory hit.
    select(browser, "height_png", "node")
    run = edit_and_wait(browser, "bits", 8)
    assert run["reran"] == ["height_png"]
    statuses = {n["id"]: n["status"] for n in s.report()["nodes"]}
    assert statuses["height_png"] == "computed"
    assert all(v == "memory" for k, v in statuses.items() if k != "height_png"), statuses


def test_an_invalid_value_shows_the_validators_message(studio_of, browser):
    s = studio_of(ROOT / "graphs" / "quickstart.json")
    browser.get(s.url)
    wait_loaded(browser)
    select(browser, "surface", "node")
    set_field(browser, "size", 2)
    shown = wait(browser, """const e = document.querySelector('#tab-node .param-error[data-param="size"]');
        return e && e.textContent;""", 30, "the error message")
    cli = subprocess.run([BIN, "validate", str(s.graph), "--set", "surface.size=2"],
                         capture_output=True, text=True)
    assert cli.returncode == 2
    # `validate` prints "<file>: <message>"; the studio shows the same message.
    messages = [line.split(": ", 1)[1] for line in cli.stderr.splitlines() if "surface" in line and ": " in line]
    assert any(m.strip() in shown or shown.strip() in m for m in messages), (shown, cli.stderr)
    assert "size" in shown
    # Refused: the graph and its file keep the old value, and nothing re-ran.
    state = json.loads(s.get("/api/state")[1])
    assert next(n for n in state["nodes"] if n["id"] == "surface")["params"]["size"] == 256
    shot(browser, "studio-invalid-value.png")


BTF_GRAPH = {
    "mesoflow": 1,
    "description": "A small captured BTF for the studio's BTF browser",
    "nodes": {
        "surface": {"kind": "heightfield.procedural",
                    "params": {"pattern": "bumps", "size": 32, "count": 4, "depth": 4.0}},
        "capture": {"kind": "btf.capture", "inputs": {"height": "surface.height"},
                    "params": {"views": {"thetas": [0, 30, 60], "phis": [0, 90, 180, 270]},
                               "lights": {"thetas": [0, 30, 60], "phis": [0, 90, 180, 270]}}},
        "pca": {"kind": "btf.pca", "inputs": {"btf": "capture.btf"}, "params": {"rank": 4}},
    },
}


def test_the_btf_browser_shows_the_chosen_direction_pair(studio_of, browser, tmp_path):
    g = tmp_path / "btf_small.json"
    g.write_text(json.dumps(BTF_GRAPH, indent=2))
    s = studio_of(g)
    browser.get(s.url)
    wait_loaded(browser)
    select(browser, "capture", "preview")
    wait(browser, "return document.querySelector('#btf-pair')?.dataset.pair !== undefined")
    first = canvas_data(browser)
    click(browser, 'svg[data-role="view"] circle.dir[data-theta="30"][data-phi="90"]')
    click(browser, 'svg[data-role="light"] circle.dir[data-theta="60"][data-phi="180"]')
    text = wait(browser, """const e = document.querySelector('#btf-pair');
        return e && e.textContent.includes('light θ 60°') ? e.textContent : null;""", 30)
    assert "view θ 30° φ 90°, light θ 60° φ 180°" in text
    pair = int(browser.execute_script("return document.querySelector('#btf-pair').dataset.pair"))
    meta = json.loads(s.get("/api/value?node=capture&port=btf")[1])
    v = meta["pairs"][pair]
    assert [round(x) for x in v] == [30, 90, 60, 180]
    second = canvas_data(browser)
    assert second != first
    shot(browser, "studio-btf-browser.png")


@pytest.mark.slow
def test_acceptance_mdf_render_rank_change_reruns_only_what_it_affects(studio_of, browser):
    s = studio_of(ROOT / "graphs" / "mdf_render.json")
    graph = json.loads(s.graph.read_text())
    browser.get(s.url)
    wait_loaded(browser)
    select(browser, "torus_mdf", "preview")
    before = canvas_data(browser)
    select(browser, "pca", "node")
    run = edit_and_wait(browser, "rank", 2)
    affected = descendants(graph, "pca")
    assert set(run["reran"]) == affected
    statuses = {n["id"]: n["status"] for n in s.report()["nodes"]}
    for nid in graph["nodes"]:
        if nid in affected:
            assert statuses[nid] == "computed", nid
        elif nid in statuses:
            assert statuses[nid] == "memory", (nid, statuses[nid])
    # The render shown is the new one.
    select(browser, "torus_mdf", "preview")
    after = wait(browser, f"""const c = document.querySelector('#preview-canvas');
        const d = c && +c.dataset.draws > 0 ? c.toDataURL() : null;
        return d && d !== {json.dumps(before)} ? d : null;""", 60, "the new render")
    assert after != before
    shot(browser, "studio-mdf-render.png")


def test_a_sweep_started_in_the_studio_fills_its_table_and_charts(studio_of, browser):
    from selenium.webdriver.support.ui import Select

    s = studio_of(ROOT / "graphs" / "quickstart.json")
    browser.get(s.url)
    wait_loaded(browser)
    click(browser, '#tabs button[data-tab="sweep"]')
    Select(browser.find_element("css selector", "#sweep-param")).select_by_value("surface.depth")
    browser.find_element("css selector", "#sweep-values").send_keys("2, 4, 8")
    click(browser, '#sweep-measures input[value="normals.rms_slope"]')
    click(browser, "#sweep-start")
    wait(browser, """const t = document.querySelector('#sweep-table');
        const imgs = document.querySelectorAll('#sweep-results img.chart');
        return t && t.querySelectorAll('tr').length === 4 && imgs.length > 0 &&
               [...imgs].every(i => i.complete && i.naturalWidth > 0);""", 120, "the sweep's table and charts")
    cells = browser.execute_script("""return [...document.querySelectorAll('#sweep-table tr')].slice(1)
        .map(r => [...r.querySelectorAll('td')].map(td => td.textContent));""")
    assert [c[0] for c in cells] == ["2", "4", "8"]
    # Deeper weave, steeper normals: the measure grows with the depth.
    slopes = [float(c[1]) for c in cells]
    assert slopes[0] < slopes[1] < slopes[2], slopes
    assert (s.dir / "out" / "sweep" / "sweep.csv").exists()
    shot(browser, "studio-sweep.png")


def test_a_plan_against_the_truth_is_shown_and_applied(studio_of, browser, tmp_path):
    """The Plan tab: a budget no model meets on this small translucent sphere (as in
    tests/plan_truth.rs), the candidates as measured with brute force chosen, the probe's truth,
    the render as given and the plan with their FLIP maps against the truth drawn, then applied
    as an edit: the render becomes render.reference in the graph being edited."""
    from selenium.webdriver.common.keys import Keys

    g = json.loads((ROOT / "graphs" / "family_translucent.json").read_text())
    g["nodes"]["mesh"]["params"]["segments"] = [32, 16]
    for n in ("ours", "truth"):
        g["nodes"][n]["params"]["camera"]["resolution"] = [32, 24]
    g["nodes"]["lighting"]["params"]["max_points"] = 2000
    g["nodes"]["lighting"]["params"]["shadow_resolution"] = 128
    g["nodes"]["truth"]["params"]["samples"] = 64
    src = tmp_path / "src"
    src.mkdir()
    (src / "translucent.json").write_text(json.dumps(g, indent=2))
    s = studio_of(src / "translucent.json")
    browser.get(s.url)
    wait_loaded(browser)
    click(browser, '#tabs button[data-tab="plan"]')
    budget = browser.find_element("css selector", "#plan-budget")
    budget.send_keys(Keys.CONTROL, "a")
    budget.send_keys("0.06")
    click(browser, "#plan-start")
    wait(browser, """return document.querySelector('#plan-table tr.chosen') &&
        document.querySelector('#plan-apply') ? true : null;""", 300, "the plan's candidates")
    rows = browser.execute_script("""return [...document.querySelectorAll('#plan-table tr')].slice(1)
        .map(r => r.querySelector('td').textContent);""")
    assert len(rows) >= 3, rows
    chosen = browser.execute_script("return document.querySelector('#plan-table tr.chosen td').textContent")
    assert "brute force" in chosen, rows
    # The probe's truth, the render as given, the plan and their FLIP maps, each drawn.
    names = ["truth", "given", "planned", "given_error", "planned_error"]
    wait(browser, """return %s.every(n => {
        const c = document.querySelector('#plan-preview-' + n);
        return c && c.dataset.draws && c.width > 0; }) ? true : null;""" % json.dumps(names),
         120, "the plan's previews")
    browser.execute_script("document.querySelector('#plan-why').scrollIntoView()")
    shot(browser, "studio-plan.png")
    click(browser, "#plan-apply")
    wait(browser, """const s = window.studio.state;
        const n = s && s.nodes.find(n => n.id === 'ours');
        return n && n.kind === 'render.reference' ? true : null;""", 60, "the plan applied")


def test_a_subgraph_box_opens_in_place_onto_its_nodes(studio_of, browser):
    """graphs/btf_capture.json uses graphs/woven_capture.json as its node `tile`: the box opens in
    place onto the nodes inside it (inside its frame, wired to each other), each one's status,
    panel and preview under its path, and closes again."""
    s = studio_of(ROOT / "graphs" / "btf_capture.json")
    browser.get(s.url)
    wait_loaded(browser)
    assert not browser.find_elements("css selector", 'g.node[data-id="tile/surface"]')
    click(browser, 'g.node[data-id="tile"] text[data-toggle="tile"]')
    inner = json.loads(wait(browser, """const g = document.querySelectorAll('g.node[data-id^="tile/"]');
        return g.length ? JSON.stringify([...g].map(e => e.dataset.id)) : null;""", 30, "the nodes inside tile"))
    state = browser.execute_script("return window.studio.state")
    tile = next(n for n in state["nodes"] if n["id"] == "tile")
    assert sorted(inner) == sorted(tile["inner"])
    # Inside the frame, and wired: the capture reads the surface inside the box.
    inside = browser.execute_script("""const r = e => e.getBoundingClientRect();
        const f = r(document.querySelector('g.node[data-id="tile"] rect.body'));
        return [...document.querySelectorAll('g.node[data-id^="tile/"] rect.body')].every(e => {
          const b = r(e); return b.left >= f.left && b.right <= f.right && b.top >= f.top && b.bottom <= f.bottom; });""")
    assert inside
    edges = browser.execute_script("return document.querySelectorAll('#viewport path.edge').length")
    assert edges >= len(state["nodes"]) - 1
    # An inner node: its status from the report, its panel says where to set it, its preview.
    assert browser.execute_script(
        "return document.querySelector('g.node[data-id=\"tile/surface\"]').dataset.status") in ("computed", "disk", "memory")
    select(browser, "tile/surface", "node")
    note = wait(browser, "return document.querySelector('#inner-note')?.textContent", 10, "the inner node's note")
    assert "tile" in note and "surface" in note
    click(browser, '#tabs button[data-tab="preview"]')
    wait(browser, "return document.querySelector('#preview-body')?.dataset.view", 60, "the inner node's preview")
    shot(browser, "studio-subgraph-open.png")
    click(browser, 'g.node[data-id="tile"] text[data-toggle="tile"]')
    wait(browser, "return !document.querySelector('g.node[data-id=\"tile/surface\"]')", 10, "the box to close")
