#!/usr/bin/env python3
"""Checks that a self-contained HTML report renders in headless Chromium.

Usage: tools/check_html.py REPORT.html [--min-images N] [--screenshot OUT.png] [--timeout S]

1. `chromium --headless --no-sandbox --disable-gpu --virtual-time-budget=5000 --dump-dom file://...`:
   the dumped DOM must hold an element with id "report-status" whose text is "ok N/N" (N >= --min-images,
   default 1). The page's own inline script sets it after checking that every <img> is complete with
   naturalWidth > 0 (see the delimited script block in tests/data/report_sample.html, which the report
   copies verbatim), so a broken embedded image, a script error or a page that never loads all fail.
2. `chromium ... --screenshot=... --window-size=1200,2000`: the PNG must decode and not be one flat colour.
Prints one JSON object. Exit 0 when rendered, 1 when not, 77 ("skipped: ..." on stderr) when chromium is
missing (set CHROMIUM to use another binary). Standard library only.
"""
import argparse
import html.parser
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zlib

BASE_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000"]


class StatusFinder(html.parser.HTMLParser):
    """Collects the text of the element with id="report-status" (nested elements included)."""

    VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.depth = 0          # > 0 while inside the status element
        self.found = False
        self.text = []

    def handle_starttag(self, tag, attrs):
        if self.depth:
            if tag not in self.VOID:
                self.depth += 1
        elif not self.found and dict(attrs).get("id") == "report-status":
            self.found = True
            if tag not in self.VOID:
                self.depth = 1

    def handle_endtag(self, tag):
        if self.depth:
            self.depth -= 1

    def handle_data(self, data):
        if self.depth:
            self.text.append(data)


def paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def add_bytes(x, y):
    """Bytewise (x + y) mod 256 of two equal-length byte strings, without a Python loop per byte."""
    n = len(x)
    if n == 0:
        return b""
    a, b = int.from_bytes(x, "little"), int.from_bytes(y, "little")
    even = int.from_bytes(b"\xff\x00" * (n // 2) + b"\xff" * (n % 2), "little")
    odd = even << 8
    s = (((a & even) + (b & even)) & even) | (((a & odd) + (b & odd)) & odd)
    return (s & ((1 << (8 * n)) - 1)).to_bytes(n, "little")


def decode_png(data):
    """Returns (width, height, bytes per pixel, list of unfiltered rows) of an 8-bit non-interlaced PNG."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG file")
    pos, idat, ihdr = 8, [], None
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
    if ihdr is None:
        raise ValueError("PNG without IHDR")
    width, height, depth, ctype, _, _, interlace = ihdr
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(ctype)
    if depth != 8 or channels is None or interlace:
        raise ValueError(f"unsupported PNG (bit depth {depth}, colour type {ctype}, interlace {interlace})")
    raw = zlib.decompress(b"".join(idat))
    stride = width * channels
    if len(raw) < height * (stride + 1):
        raise ValueError("truncated PNG data")
    rows, prev = [], bytes(stride)
    for y in range(height):
        f = raw[y * (stride + 1)]
        line = raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)]
        if f == 0:
            cur = line
        elif f == 2:
            cur = add_bytes(line, prev)
        elif f in (1, 3, 4):
            out = bytearray(line)
            for i in range(stride):
                left = out[i - channels] if i >= channels else 0
                if f == 1:
                    out[i] = (out[i] + left) & 0xFF
                elif f == 3:
                    out[i] = (out[i] + ((left + prev[i]) >> 1)) & 0xFF
                else:
                    upleft = prev[i - channels] if i >= channels else 0
                    out[i] = (out[i] + paeth(left, prev[i], upleft)) & 0xFF
            cur = bytes(out)
        else:
            raise ValueError(f"bad PNG filter type {f} in row {y}")
        rows.append(cur)
        prev = cur
    return width, height, channels, rows


def screenshot_stats(path):
    with open(path, "rb") as f:
        width, height, channels, rows = decode_png(f.read())
    first = rows[0][:channels]
    flat_row = first * width
    flat = all(r == flat_row for r in rows)
    counts = {}
    step = 8                                        # a 1-in-64 grid of pixels for the colour statistics
    for y in range(0, height, step):
        r = rows[y]
        for x in range(0, width, step):
            px = r[x * channels:(x + 1) * channels]
            counts[px] = counts.get(px, 0) + 1
    total = sum(counts.values())
    return {"width": width, "height": height, "channels": channels, "flat": flat,
            "colours_sampled": len(counts),
            "background_fraction": round(max(counts.values()) / total, 4)}


def run(cmd, timeout):
    t0 = time.monotonic()
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=timeout)
    return proc, round(time.monotonic() - t0, 3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("html", help="the HTML file to check")
    ap.add_argument("--min-images", type=int, default=1, help="fewest <img> the page must have (default 1)")
    ap.add_argument("--screenshot", metavar="OUT.png", help="keep the screenshot here")
    ap.add_argument("--timeout", type=float, default=120, help="seconds per Chromium run (default 120)")
    args = ap.parse_args()

    browser = os.environ.get("CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    if not browser or not shutil.which(browser):
        print("skipped: chromium not found (Debian: apt-get install --no-install-recommends chromium)",
              file=sys.stderr)
        return 77
    path = os.path.abspath(args.html)
    if not os.path.isfile(path):
        print(f"error: {args.html}: no such file", file=sys.stderr)
        return 1
    url = "file://" + path
    result = {"file": path, "rendered": False, "errors": []}
    work = tempfile.mkdtemp(prefix="check_html_")
    try:
        # A fresh profile per run: no state from other runs, no profile lock shared with a parallel test.
        dom_cmd = [browser] + BASE_FLAGS + [f"--user-data-dir={work}/profile-dom", "--dump-dom", url]
        proc, result["dom_seconds"] = run(dom_cmd, args.timeout)
        finder = StatusFinder()
        finder.feed(proc.stdout.decode("utf-8", "replace"))
        status = " ".join("".join(finder.text).split()) if finder.found else None
        result["status"] = status
        m = re.fullmatch(r"ok (\d+)/(\d+)", status or "")
        if proc.returncode != 0:
            result["errors"].append(f"--dump-dom: chromium exited {proc.returncode}")
        if not finder.found:
            result["errors"].append('no element with id "report-status" in the rendered DOM')
        elif not m or m.group(1) != m.group(2):
            result["errors"].append(f'report-status is "{status}", not "ok N/N"')
        elif int(m.group(2)) < args.min_images:
            result["errors"].append(f"{m.group(2)} images, fewer than {args.min_images}")
        if m:
            result["images"] = int(m.group(2))

        shot = os.path.abspath(args.screenshot) if args.screenshot else os.path.join(work, "screenshot.png")
        if os.path.exists(shot):
            os.remove(shot)
        shot_cmd = [browser] + BASE_FLAGS + [f"--user-data-dir={work}/profile-shot", "--hide-scrollbars",
                                             "--window-size=1200,2000", f"--screenshot={shot}", url]
        proc2, result["screenshot_seconds"] = run(shot_cmd, args.timeout)
        if proc2.returncode != 0:
            result["errors"].append(f"--screenshot: chromium exited {proc2.returncode}")
        if not os.path.isfile(shot):
            result["errors"].append("no screenshot written")
        else:
            try:
                stats = screenshot_stats(shot)
                result["screenshot"] = stats
                if stats["flat"]:
                    result["errors"].append("the screenshot is one flat colour")
            except (ValueError, zlib.error, struct.error) as e:
                result["errors"].append(f"screenshot does not decode: {e}")
        result["commands"] = [" ".join(dom_cmd), " ".join(shot_cmd)]
        result["rendered"] = not result["errors"]
        if not result["rendered"]:
            lines = (proc.stderr + proc2.stderr).decode("utf-8", "replace").strip().splitlines()
            tail = [ln for ln in lines if "dbus" not in ln][-6:]   # no D-Bus in a container: noise
            result["chromium_stderr_tail"] = tail
    except subprocess.TimeoutExpired as e:
        result["errors"].append(f"chromium did not finish in {e.timeout} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(result))
    return 0 if result["rendered"] else 1


if __name__ == "__main__":
    sys.exit(main())
