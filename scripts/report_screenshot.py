"""A screenshot of a result's interactive report, taken by headless Chromium (the README's picture).

    python scripts/report_screenshot.py RESULT_DIR docs/report.png

Writes RESULT_DIR/report.html if missing; Debian's chromium (apt install chromium) drives WebGL through
SwiftShader, as tests/test_boundary.py does.
"""

import shutil
import sys
from pathlib import Path

from playwright.sync_api import sync_playwright

from casadi_ws.io.report import write_report
from casadi_ws.workspace.result import load_result


def main(result_dir: str, png: str) -> None:
    page_file = Path(result_dir) / "report.html"
    if not page_file.is_file():
        write_report(load_result(result_dir), page_file)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"),
                                    args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
        page = browser.new_page(viewport={"width": 1400, "height": 760})
        page.goto(page_file.resolve().as_uri())
        page.wait_for_selector("#workspace .gl-container canvas", timeout=60000)
        page.wait_for_timeout(1500)
        page.screenshot(path=png)
        browser.close()


if __name__ == "__main__":
    main(*sys.argv[1:3])
