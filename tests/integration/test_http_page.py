"""The status page at `/` in a real browser: Debian's chromium, headless, driven by selenium.

It shows the configured channels and a value that changes live (over the WebSocket), logs no
console error, and makes no request off the machine (every request and WebSocket the browser
opened, from its DevTools performance log, is to the daemon's loopback address). `.ci/run`
installs chromium and chromium-driver.
"""

from __future__ import annotations

import json
import shutil
import time
from urllib.parse import urlparse

import pytest

from .helpers import VEHICLE, is_type, udp_channel, udp_url, wait_for

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage")

webdriver = pytest.importorskip("selenium.webdriver")


@pytest.fixture
def browser(tmp_path):
    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
        pytest.skip("chromium and chromium-driver are not installed (.ci/run installs them)")
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path / 'chromium-profile'}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(20)
    yield driver
    driver.quit()


ROWS = "return [...document.querySelectorAll('#' + arguments[0] + ' tr')].map(r => [...r.cells].map(c => c.textContent));"


def cell(driver, table: str, row_name: str, column: int) -> str | None:
    """One cell, read in one script (the page redraws its tables every second)."""
    for cells in driver.execute_script(ROWS, table):
        if cells and cells[0] == row_name:
            return cells[column]
    return None


def wait(fn, timeout: float = 10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(0.1)
    return None


def requests_made(driver) -> list[str]:
    urls = []
    for entry in driver.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
        elif message["method"] == "Network.webSocketCreated":
            urls.append(message["params"]["url"])
    return urls


def test_page_shows_channels_live_offline_and_without_console_errors(daemon, browser, client):
    d = daemon({"channels": [udp_channel("gcs"), udp_channel("telem2")]})
    url = d.http_url()
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert wait_for(station, is_type("HEARTBEAT", VEHICLE))
    browser.get(url + "/")
    assert browser.title == "gcsd"
    # the configured channels (and the API's own), from the status WebSocket
    assert wait(lambda: cell(browser, "channels", "telem2", 1) == "udp-server")
    assert cell(browser, "channels", "gcs", 1) == "udp-server" and cell(browser, "channels", "http", 1) == "local"
    port = station.conn.port.getsockname()[1]
    assert wait(lambda: cell(browser, "channels", "gcs", 10) == f"127.0.0.1:{port}")  # the station, as a peer
    assert wait(lambda: cell(browser, "vehicles", "1", 3) == "STABILIZE")
    # a value that changes live: the http channel's packets out (our vehicle's telemetry)
    first = int(cell(browser, "channels", "http", 7))
    assert wait(lambda: int(cell(browser, "channels", "http", 7)) > first), "the counter moves"
    # the vehicle is drawn from GLOBAL_POSITION_INT frames of the MAVLink WebSocket
    assert wait(lambda: cell(browser, "vehicles", "1", 5) not in (None, "-"))
    assert wait(lambda: browser.find_element("id", "msgrate").text not in ("", "0"))
    console = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "WARNING")]
    assert console == [], console
    host = urlparse(url).netloc
    urls = requests_made(browser)
    assert any(u.startswith(f"ws://{host}/v1/ws/mavlink") for u in urls)
    assert any(u == f"{url}/favicon.ico" for u in urls), "its own favicon"
    # chrome:// (the browser's own start page) and data: never leave the process; anything on
    # the network must be the daemon's address
    network = [u for u in urls if urlparse(u).scheme in ("http", "https", "ws", "wss", "ftp")]
    assert len(network) >= 3
    off_machine = [u for u in network if urlparse(u).netloc != host]
    assert off_machine == [], off_machine


def test_page_takes_the_token_from_the_address(daemon, browser, tmp_path):
    token_file = tmp_path / "token"
    token_file.write_text("page-token\n")
    d = daemon({"channels": [udp_channel("gcs")], "http": {"address": "127.0.0.1:0", "token_file": str(token_file)}})
    browser.get(d.http_url() + "/?token=page-token")
    assert wait(lambda: cell(browser, "channels", "gcs", 1) == "udp-server")
    browser.get(d.http_url() + "/?token=page-token#again")  # kept in the session: still live
    assert wait(lambda: cell(browser, "channels", "http", 1) == "local")
    console = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert console == [], console
