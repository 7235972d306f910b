"""The built documentation site, opened in headless Chromium: its pages render with no console
error, their figures load, and its search finds the names a newcomer looks for.

``make docs`` builds the site and then runs these tests with ``PIEZOHYST_SITE`` naming the
built folder; without it (``make test``) they skip: the site is built apart from the tests.
The browser is Playwright's own Chromium where it is installed, else the system's
(``chromium`` from Debian, or ``PIEZOHYST_CHROMIUM``). ``PIEZOHYST_REQUIRE_BROWSER=1`` (CI)
turns a missing browser into a failure instead of a skip.
"""

from __future__ import annotations

import functools
import http.server
import importlib
import inspect
import os
import shutil
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

SITE = os.environ.get("PIEZOHYST_SITE")
if not SITE:
    pytest.skip("the built site is checked by `make docs`", allow_module_level=True)
DOCS = Path(__file__).resolve().parents[2] / "docs"


def _browser_path() -> str | None:
    for name in (os.environ.get("PIEZOHYST_CHROMIUM"), "chromium", "chromium-browser",
                 "google-chrome"):  # fmt: skip
        if name and shutil.which(name):
            return shutil.which(name)
    return None


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    """The built site over HTTP on a free local port, as a host would serve it."""

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args: Any) -> None:
            """Each request is not worth a line of the test's output."""

    handler = functools.partial(Quiet, directory=SITE)
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
    with sync_playwright() as p:
        try:
            found = p.chromium.launch()  # Playwright's own browser, where it was installed
        except Exception:
            path = _browser_path()
            if path is None:
                if os.environ.get("PIEZOHYST_REQUIRE_BROWSER") == "1":
                    pytest.fail("no Chromium: install Debian's `chromium` or run "
                                "`playwright install chromium`")  # fmt: skip
                pytest.skip("no Chromium here (Debian's `chromium`, or `playwright install`)")
            found = p.chromium.launch(executable_path=path)
        yield found
        found.close()


def _open(browser: Any, url: str) -> tuple[Any, list[str]]:
    """The page loaded, and every console error and uncaught exception it raised.

    A request to another host (MathJax from its CDN, on a page with equations) is not the
    site's: where the machine is offline it fails, and its console line with it; those are
    left out. Every request to the site itself must load."""
    page = browser.new_page()
    errors: list[str] = []
    offline: list[str] = []
    local = url.split("/")[2]

    def failed(request: Any) -> None:
        (errors if request.url.split("/")[2] == local else offline).append(
            f"failed to load {request.url}"
        )

    def console(message: Any) -> None:
        where = (message.location or {}).get("url", "")
        external = where and where.split("/")[2] != local
        if message.type == "error" and not (offline and "ERR_" in message.text and external):
            errors.append(f"console: {message.text}")

    page.on("console", console)
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    page.on("requestfailed", failed)
    response = page.goto(url, wait_until="load")
    assert response is not None and response.ok, f"{url}: {response and response.status}"
    page.wait_for_load_state("networkidle")
    return page, errors


def _images(page: Any) -> list[tuple[str, bool]]:
    """Every <img> of the page and whether it loaded (decoded, with a width)."""
    return page.eval_on_selector_all(
        "img", "els => els.map(e => [e.src, e.complete && e.naturalWidth > 0])"
    )


PAGES = [
    "index.html",
    "api/index.html",
    "api/piezohyst.html",
    "api/generated/piezohyst.Compensator.html",
    "api/generated/piezohyst.calibrate_gain.html",
    "auto_examples/index.html",
    "auto_examples/plot_01_paper_experiment.html",
    "auto_examples/plot_10_xy_raster.html",
    "realtime.html",
]


@pytest.mark.parametrize("path", PAGES)
def test_page_renders_with_no_console_error_and_every_image_loaded(
    browser: Any, server: str, path: str
) -> None:
    page, errors = _open(browser, f"{server}/{path}")
    assert errors == []
    assert page.title(), path
    assert page.locator("main, article").first.inner_text().strip(), f"{path} shows nothing"
    broken = [src for src, ok in _images(page) if not ok]
    assert broken == []
    page.close()


def test_every_gallery_example_shows_its_figures(browser: Any, server: str) -> None:
    examples = sorted(Path(SITE or "").glob("auto_examples/plot_*.html"))
    assert len(examples) >= 10, [e.name for e in examples]
    for example in examples:
        page, errors = _open(browser, f"{server}/auto_examples/{example.name}")
        figures = [ok for src, ok in _images(page) if "/_images/sphx_glr_" in src]
        assert figures and all(figures), f"{example.name}: figures {figures}"
        assert errors == [], example.name
        page.close()


@pytest.mark.parametrize("name", ["Compensator", "calibrate_gain", "select_model"])
def test_search_finds_the_names_a_newcomer_looks_for(browser: Any, server: str, name: str) -> None:
    page, errors = _open(browser, f"{server}/search.html?q={name}")
    page.wait_for_selector("#search-results ul.search li", timeout=30_000)
    found = page.locator("#search-results ul.search li a").all_inner_texts()
    assert any(name in text for text in found), found[:10]
    assert errors == []
    page.close()


def test_every_public_name_has_a_page_with_its_parameters() -> None:
    """Each class and function of every face in ``docs/api_pages.py`` has a page, on one face
    or another, and a callable that takes arguments shows its Parameters section."""
    sys.path.insert(0, str(DOCS))
    faces = importlib.import_module("api_pages").FACES
    pages = {p.stem: p for p in Path(SITE or "").glob("api/generated/*.html")}
    seen: dict[int, str] = {}
    missing, no_parameters = [], []
    for module_name, _ in faces:
        module = importlib.import_module(module_name)
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)) or id(obj) in seen:
                continue
            seen[id(obj)] = page = f"{module_name}.{name}"
            if page not in pages:
                missing.append(page)
                continue
            takes = inspect.isfunction(obj) and len(inspect.signature(obj).parameters) > 0
            if takes and "Parameters" not in pages[page].read_text():
                no_parameters.append(page)
    assert len(seen) > 150
    assert missing == []
    assert no_parameters == [], no_parameters
