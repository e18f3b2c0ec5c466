"""Headless Chromium for the browser tests (Debian's ``chromium`` and ``chromium-driver`` through Selenium)."""

import os

import pytest

CHROMIUM = os.environ.get("PORECAD_CHROMIUM", "/usr/bin/chromium")
DRIVER = os.environ.get("PORECAD_CHROMEDRIVER", "/usr/bin/chromedriver")


def browser_or_skip():
    """Selenium's webdriver module; fails (with ``PORECAD_REQUIRE_BROWSER``, as in CI) or skips without a browser."""
    webdriver = pytest.importorskip("selenium.webdriver")
    if not (os.path.exists(CHROMIUM) and os.path.exists(DRIVER)):
        if os.environ.get("PORECAD_REQUIRE_BROWSER"):
            pytest.fail(f"no browser: {CHROMIUM} and {DRIVER} are needed (apt-get install chromium chromium-driver)")
        pytest.skip("no chromium / chromedriver")
    return webdriver
