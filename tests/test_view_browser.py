"""clpost view in a real browser: Debian's headless chromium driven by Selenium (.ci/run installs
chromium and chromium-driver; nothing is downloaded at test time). The server is the real command
(`clpost view --no-browser --port 0`) in a subprocess, on the demo scene at 480x270."""
from __future__ import annotations

import io
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
DRIVER = shutil.which("chromedriver")
if CHROMIUM is None or DRIVER is None:
    pytest.skip("Debian's chromium and chromium-driver are not installed (apt-get install chromium "
                "chromium-driver; .ci/run installs them)", allow_module_level=True)
webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (pip install '.[test]')")
pytest.importorskip("trame", reason="trame (pip install '.[view]')")

from PIL import Image  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402

SHOTS = Path(os.environ.get("CLPOST_VIEW_SHOTS", "")) if os.environ.get("CLPOST_VIEW_SHOTS") else None


@pytest.fixture(scope="module")
def server():
    cmd = [sys.executable, "-m", "clpost.cli", "view", "--no-browser", "--port", "0", "--size", "480x270",
           "--frames", "2", "--quality", "draft", "--f-number", "2", "--focus", "40"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url, lines, t0 = None, [], time.time()
    while time.time() - t0 < 240:
        line = p.stdout.readline()
        if not line:
            break
        lines.append(line)
        m = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
        if m:
            url = m.group(1)
            break
    if url is None:
        p.kill()
        pytest.fail("clpost view printed no URL:\n" + "".join(lines))
    yield p, url
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(30)
        except subprocess.TimeoutExpired:
            p.kill()


@pytest.fixture(scope="module")
def browser(server):
    opts = webdriver.ChromeOptions()
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
              "--window-size=1600,1100"):
        opts.add_argument(a)
    opts.binary_location = CHROMIUM
    d = webdriver.Chrome(service=webdriver.ChromeService(DRIVER), options=opts)
    d.get(server[1])
    yield d
    d.quit()


def wait_for(d, cond, timeout=120.0, what="condition"):
    t0 = time.time()
    while time.time() - t0 < timeout:
        v = cond()
        if v:
            return v
        time.sleep(0.2)
    pytest.fail(f"timed out waiting for {what}; renders {renders(d)}, status: {status(d)!r}")


def status(d) -> str:
    try:
        return d.find_element(By.ID, "status").text
    except Exception:  # noqa: BLE001 - only for the failure message
        return "?"


def renders(d) -> int:
    return int(d.execute_script("var e = document.getElementById('renders'); return e ? e.textContent || 0 : 0"))


def settle(d, after: int) -> None:
    """Wait until a frame newer than render number ``after`` is shown and nothing is pending."""
    wait_for(d, lambda: renders(d) > after, what=f"a render after #{after}")
    last = renders(d)
    time.sleep(1.5)
    while renders(d) != last:  # still coming (draft, then the idle render)
        last = renders(d)
        time.sleep(1.5)


def shot(d, elem_id: str, name: str) -> np.ndarray:
    png = d.find_element(By.ID, elem_id).screenshot_as_png
    if SHOTS is not None:
        SHOTS.mkdir(parents=True, exist_ok=True)
        (SHOTS / f"{name}.png").write_bytes(png)
    return np.asarray(Image.open(io.BytesIO(png)).convert("L"), np.float64)


def local_contrast(img: np.ndarray, box) -> float:
    """Mean absolute Laplacian (a focus measure) inside box = (x0, y0, x1, y1) in 0..1 of the image."""
    h, w = img.shape
    x0, y0, x1, y1 = int(box[0] * w), int(box[1] * h), int(box[2] * w), int(box[3] * h)
    a = img[y0:y1, x0:x1]
    lap = 4 * a[1:-1, 1:-1] - a[:-2, 1:-1] - a[2:, 1:-1] - a[1:-1, :-2] - a[1:-1, 2:]
    return float(np.abs(lap).mean())


def drag_slider(d, label: str, dx: int) -> None:
    thumb = d.find_element(By.CSS_SELECTOR, f"#slider-{label} .v-slider-thumb")
    ActionChains(d).click_and_hold(thumb).move_by_offset(dx // 2, 0).pause(0.2).move_by_offset(
        dx - dx // 2, 0).pause(0.2).release().perform()


def text_value(d, label: str) -> str:
    return d.find_element(By.CSS_SELECTOR, f"#text-{label} input").get_attribute("value")


NEAR = (0.10, 0.75, 0.32, 0.98)
"""The red-white checker ball in the demo's bottom-left corner (≈ 1.4 m; the far wall ≈ 10+ m)."""


def test_page_drag_and_tap_to_focus(server, browser, tmp_path):
    d = browser
    wait_for(d, lambda: renders(d) > 0, what="the first frame")
    settle(d, 0)
    assert "f/2 " in status(d) and "focus 40 m" in status(d), status(d)

    # drag the f-number slider to the right: stopped down, the plan is reused (scalar)
    n = renders(d)
    drag_slider(d, "f-number", 60)
    settle(d, n)
    f_stopped = float(text_value(d, "f-number"))
    assert f_stopped > 2.5, text_value(d, "f-number")
    assert "plan reused" in status(d) and "no rebuild" in status(d), status(d)
    # and back wide open, so the focus is what decides sharpness below
    n = renders(d)
    drag_slider(d, "f-number", -200)
    settle(d, n)
    assert float(text_value(d, "f-number")) < f_stopped

    # drag focus: its text follows the slider
    before = text_value(d, "focus")
    n = renders(d)
    drag_slider(d, "focus", 30)
    settle(d, n)
    assert text_value(d, "focus") != before

    # put the focus far again by the text field (CLI syntax), then measure the near ball
    field = d.find_element(By.CSS_SELECTOR, "#text-focus input")
    n = renders(d)
    field.clear()
    field.send_keys("40\n")
    settle(d, n)
    assert "focus 40 m" in status(d), status(d)
    blurred = shot(d, "frame", "view_far_focus")
    hist_before = shot(d, "histogram", "view_hist_before")
    c_blurred = local_contrast(blurred, NEAR)

    # click the ball: focus from the depth pass at that pixel
    img = d.find_element(By.ID, "frame")
    w, h = img.size["width"], img.size["height"]
    n = renders(d)
    ActionChains(d).move_to_element_with_offset(img, int((0.2 - 0.5) * w), int((0.88 - 0.5) * h)).click().perform()
    settle(d, n)
    m = re.search(r"focus ([\d.]+) m", status(d))
    assert m and 0.5 < float(m.group(1)) < 5, status(d)
    sharp = shot(d, "frame", "view_tap_focus")
    c_sharp = local_contrast(sharp, NEAR)
    assert c_sharp > 1.5 * c_blurred, (c_sharp, c_blurred)

    # exposure: +2 EV moves the histogram
    field = d.find_element(By.CSS_SELECTOR, "#text-ev input")
    n = renders(d)
    field.clear()
    field.send_keys("3\n")
    settle(d, n)
    hist_after = shot(d, "histogram", "view_hist_after")
    assert hist_after.shape == hist_before.shape
    assert np.abs(hist_after - hist_before).mean() > 3.0

    # a structural parameter builds a plan, and the page says so
    field = d.find_element(By.CSS_SELECTOR, "#text-blades input")
    n = renders(d)
    field.clear()
    field.send_keys("5\n")
    settle(d, n)
    assert "plan built" in status(d) and "blades: structural" in status(d), status(d)

    # the command line carries the settings; the copy button raises nothing in the page
    copy = d.find_element(By.ID, "copy")
    d.execute_script("arguments[0].scrollIntoView({block: 'center'});", copy)
    time.sleep(0.3)
    copy.click()
    time.sleep(0.5)
    errors = [e for e in d.get_log("browser") if e["level"] == "SEVERE" and "/paraview/" not in e["message"]]
    assert not errors, errors
    cmd = d.find_element(By.ID, "command").get_attribute("value")
    assert cmd.startswith("clpost process ") and "--ev +3" in cmd and "--focus " in cmd and "--blades 5" in cmd, cmd

    # save the camera track: a file clpost process --camera-track reads, with the page's values
    from clpost.camera_track import load_track

    path = d.find_element(By.CSS_SELECTOR, "#track-path input")
    path.send_keys(Keys.CONTROL, "a")
    path.send_keys(str(tmp_path / "track.json"))
    save = d.find_element(By.ID, "save-track")
    d.execute_script("arguments[0].scrollIntoView({block: 'center'});", save)
    wait_for(d, lambda: d.execute_script("return document.querySelector('#track-path input').value")
             .endswith("track.json"), timeout=10, what="the track path")
    time.sleep(0.5)
    save.click()
    wait_for(d, lambda: (tmp_path / "track.json").exists(), timeout=20, what="the track file")
    values = load_track(tmp_path / "track.json").values_at(1)
    assert values["blades"] == 5 and values["exposure_compensation_ev"] == 3.0


def test_listens_on_loopback_only(server):
    port = int(server[1].rstrip("/").rsplit(":", 1)[1])
    tcp = Path("/proc/net/tcp")
    if not tcp.exists():
        pytest.skip("no /proc/net/tcp to read the listening address from")
    listening = [line.split()[1] for line in tcp.read_text().splitlines()[1:]
                 if line.split()[3] == "0A" and int(line.split()[1].split(":")[1], 16) == port]
    assert listening == ["0100007F:%04X" % port], listening  # 127.0.0.1 only (no 0.0.0.0, no IPv6 any)
    tcp6 = Path("/proc/net/tcp6")
    if tcp6.exists():
        assert not [line for line in tcp6.read_text().splitlines()[1:]
                    if line.split()[3] == "0A" and int(line.split()[1].split(":")[1], 16) == port]


def test_sigint_stops_cleanly(server, browser):
    p, _ = server
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0, out
    assert "clpost view: stopped" in out
    assert "Traceback" not in out
