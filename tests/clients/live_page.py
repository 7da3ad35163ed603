#!/usr/bin/env python3
"""Loads squall's live page in headless Chromium while a run goes and
checks what it shows, through the Chrome DevTools Protocol (written here
from the protocol's documentation; no browser driver library).

usage: live_page.py URL SCREENSHOT.png COMPONENT...

Waits for the page to say the run is running, then for the received
count of the last COMPONENT to change between two reads of the DOM;
checks every COMPONENT has a row and a node in the graph; saves a
screenshot. Prints one JSON line of what it read; exits 1 on a failed
check.
"""

import asyncio
import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

import websockets

LIMIT_S = 60


def chromium():
    # ./test.sh says which one it found or installed.
    if os.environ.get("SQUALL_CHROMIUM"):
        return os.environ["SQUALL_CHROMIUM"]
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    sys.exit("no Chromium on PATH (Debian: apt-get install chromium)")


class Page:
    def __init__(self, ws):
        self.ws = ws
        self.next_id = 0

    async def call(self, method, **params):
        self.next_id += 1
        mine = self.next_id
        await self.ws.send(json.dumps({"id": mine, "method": method, "params": params}))
        while True:
            reply = json.loads(await self.ws.recv())
            if reply.get("id") == mine:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    async def eval(self, expression):
        result = await self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        return result["result"].get("value")


READ = """(() => {
  const rows = {};
  document.querySelectorAll('#components tr.component').forEach(tr => {
    const cell = f => (tr.querySelector(`[data-field="${f}"]`) || {}).textContent;
    rows[tr.dataset.key] = { received: cell('received'), emitted: cell('emitted'), queue: cell('queue'),
                             in_per_s: cell('in_per_s') };
  });
  return { status: document.getElementById('status').textContent,
           topology: document.getElementById('topology').textContent,
           nodes: [...document.querySelectorAll('#graph g.node')].map(g => g.dataset.component),
           edges: document.querySelectorAll('#graph path.edge').length,
           rows };
})()"""


async def check(url, screenshot, components):
    profile = tempfile.mkdtemp(prefix="squall-chromium-")
    browser = subprocess.Popen(
        [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--remote-debugging-port=0", f"--user-data-dir={profile}", "--window-size=1400,1000",
         "about:blank"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        port_file = os.path.join(profile, "DevToolsActivePort")
        deadline = time.monotonic() + LIMIT_S
        while not os.path.exists(port_file) or not open(port_file).read().strip():
            if time.monotonic() > deadline or browser.poll() is not None:
                sys.exit("Chromium did not open its DevTools port")
            await asyncio.sleep(0.05)
        port = open(port_file).read().split()[0]
        targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
        target = next(t for t in targets if t["type"] == "page")
        async with websockets.connect(target["webSocketDebuggerUrl"], max_size=None) as ws:
            page = Page(ws)
            await page.call("Page.enable")
            await page.call("Page.navigate", url=url)
            watched = components[-1]
            first = None
            while True:
                if time.monotonic() > deadline:
                    sys.exit(f"the page never showed {watched}'s count change while running: {first}")
                seen = await page.eval(READ)
                row = (seen or {}).get("rows", {}).get(watched)
                if seen and seen["status"] == "running" and row:
                    if first is None:
                        first = seen
                    elif row["received"] != first["rows"][watched]["received"]:
                        break
                await asyncio.sleep(0.2)
            missing = [c for c in components if c not in seen["rows"] or c not in seen["nodes"]]
            if missing:
                sys.exit(f"no row or graph node for {missing}: {seen}")
            shot = await page.call("Page.captureScreenshot", format="png")
            with open(screenshot, "wb") as f:
                f.write(base64.b64decode(shot["data"]))
            print(json.dumps({"first": first, "then": seen}))
    finally:
        browser.terminate()
        try:
            browser.wait(10)
        except subprocess.TimeoutExpired:
            browser.kill()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    asyncio.run(check(sys.argv[1], sys.argv[2], sys.argv[3:]))
