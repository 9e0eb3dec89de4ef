#!/usr/bin/env bash
# Checks a sweep's index.html as a browser shows it, in headless Chromium:
#   - the page logs nothing to the console (it has no script; any message is an error);
#   - every <img> loads and decodes in the browser (naturalWidth > 0), at a desktop and
#     at a phone width, and the page does not overflow sideways at either;
#   - every relative link and image points at a file that exists, and every image is a
#     PNG whose chunks and pixel data are complete (Python standard library only);
#   - the screenshots are not blank.
# The image check loads the page in an iframe of a small harness page written to a
# temporary folder (with --allow-file-access-from-files), so the page itself carries no
# test code.
#
# Usage: scripts/ci/html_check.sh DIR/index.html [SHOT_DIR]
#   SHOT_DIR (default: a temporary folder) receives screenshot-wide.png (1400 px) and
#   screenshot-narrow.png (480 px) to look at. CHROMIUM names the browser binary.
# Exit: 0 good, 1 a check failed, 2 usage or no browser.
set -euo pipefail

if [ $# -lt 1 ] || [ ! -f "$1" ]; then
  echo "usage: $0 DIR/index.html [SHOT_DIR]" >&2
  exit 2
fi
page=$(realpath "$1")
shots=${2:-$(mktemp -d)}
mkdir -p "$shots"
shots=$(realpath "$shots")
browser=${CHROMIUM:-$(command -v chromium || command -v chromium-browser || command -v google-chrome || true)}
if [ -z "$browser" ]; then
  echo "html_check: no Chromium found (install the Debian package chromium or set CHROMIUM)" >&2
  exit 2
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# A headless browser in a container: no sandbox (no user namespaces), no GPU.
flags=(--headless=new --no-sandbox --disable-gpu --hide-scrollbars --no-first-run
  --disable-extensions --user-data-dir="$work/profile")
fail=0

# 1. Screenshots, with the page's console messages on stderr.
for spec in wide:1400,2400 narrow:480,2400; do
  name=${spec%%:*}
  size=${spec#*:}
  timeout 120 "$browser" "${flags[@]}" --enable-logging=stderr --v=0 \
    --window-size="$size" --screenshot="$shots/screenshot-$name.png" "file://$page" \
    >"$work/$name.out" 2>"$work/$name.log" || true
  if [ ! -s "$shots/screenshot-$name.png" ]; then
    echo "FAIL: Chromium wrote no $name screenshot"
    tail -n 20 "$work/$name.log"
    fail=1
  fi
  if grep -a ':CONSOLE' "$work/$name.log" >"$work/console.txt"; then
    echo "FAIL: console messages while loading the page ($name):"
    cat "$work/console.txt"
    fail=1
  fi
done

# 2. Images as the browser loads them, links and overflow, at two widths.
page_url="file://$page"
for width in 1400 480; do
  cat >"$work/harness-$width.html" <<HTML
<!DOCTYPE html><html><body><pre id="result">no result</pre>
<iframe id="f" width="$width" height="1600"></iframe>
<script>
var f = document.getElementById('f');
f.addEventListener('load', function () {
  var out = document.getElementById('result');
  try {
    var d = f.contentDocument, bad = [], srcs = [], hrefs = [];
    for (var i = 0; i < d.images.length; i++) {
      var im = d.images[i];
      srcs.push(im.getAttribute('src'));
      if (!im.complete || im.naturalWidth === 0) bad.push(im.getAttribute('src'));
    }
    d.querySelectorAll('a[href]').forEach(function (a) { hrefs.push(a.getAttribute('href')); });
    out.textContent = JSON.stringify({width: $width, images: srcs, broken: bad, hrefs: hrefs,
      scrollWidth: d.documentElement.scrollWidth, title: d.title});
  } catch (e) { out.textContent = 'ERROR ' + e; }
});
f.src = $(printf '%s' "$page_url" | python3 -c 'import json,sys; print(json.dumps(sys.stdin.read()))');
</script></body></html>
HTML
  timeout 120 "$browser" "${flags[@]}" --allow-file-access-from-files \
    --virtual-time-budget=10000 --dump-dom "file://$work/harness-$width.html" \
    >"$work/dom-$width.html" 2>"$work/dom-$width.log" || true
done

python3 - "$page" "$work" "$shots" <<'PY' || fail=1
import html, json, os, re, struct, sys, urllib.parse, zlib

page, work, shots = sys.argv[1:4]
root = os.path.dirname(page)
bad = []

def png_pixels(path):
    """Checks a PNG's signature, chunk CRCs and that its pixel data inflate to the size
    IHDR announces; returns (width, height, rows as bytes) (rows keep their filter byte)."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG (signature)")
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        if pos + 8 > len(data):
            raise ValueError("truncated chunk header")
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        crc = data[pos + 8 + length:pos + 12 + length]
        if len(body) != length or len(crc) != 4:
            raise ValueError("truncated chunk %r" % kind)
        if zlib.crc32(kind + body) != struct.unpack(">I", crc)[0]:
            raise ValueError("bad CRC in chunk %r" % kind)
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
        pos += 12 + length
    if ihdr is None:
        raise ValueError("no IHDR")
    w, h, depth, colour, _, _, interlace = ihdr
    if w == 0 or h == 0:
        raise ValueError("empty image %dx%d" % (w, h))
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[colour]
    raw = zlib.decompress(idat)
    stride = (w * channels * depth + 7) // 8
    if interlace == 0 and len(raw) != h * (stride + 1):
        raise ValueError("pixel data %d bytes, expected %d" % (len(raw), h * (stride + 1)))
    rows = [raw[i * (stride + 1):(i + 1) * (stride + 1)] for i in range(h)] if interlace == 0 else []
    return w, h, rows

def local(ref):
    """The file a relative link points at, or None for anchors and absolute URLs."""
    if ref.startswith("#") or re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", ref):
        return None
    return os.path.join(root, urllib.parse.unquote(ref.split("#")[0]))

for width in ("1400", "480"):
    dom = open(os.path.join(work, "dom-%s.html" % width), encoding="utf-8", errors="replace").read()
    m = re.search(r'<pre id="result">(.*?)</pre>', dom, re.S)
    if not m or not m.group(1).startswith("{"):
        bad.append("harness at %s px gave no result: %s" % (width, m.group(1)[:200] if m else dom[:200]))
        continue
    r = json.loads(html.unescape(m.group(1)))
    if not r["images"]:
        bad.append("the page has no image")
    for src in r["broken"]:
        bad.append("image does not load in Chromium (%s px): %s" % (width, src))
    if r["scrollWidth"] > r["width"] + 1:
        bad.append("page overflows sideways at %s px: %s px wide" % (width, r["scrollWidth"]))
    for ref in r["images"]:
        path = local(ref)
        if path is None:
            bad.append("image is not a relative path: %s" % ref)
            continue
        try:
            if path.endswith(".svg"):
                # --figure-format svg: a well-formed SVG document with a size.
                import xml.etree.ElementTree as ET
                svg = ET.parse(path).getroot()
                if not svg.tag.endswith("svg") or not svg.get("width"):
                    raise ValueError("not an SVG document with a width")
            else:
                png_pixels(path)
        except (OSError, ValueError, zlib.error, KeyError, SyntaxError) as e:
            bad.append("image %s: %s" % (ref, e))
    for ref in r["hrefs"]:
        path = local(ref)
        if path is not None and not os.path.isfile(path):
            bad.append("link to a missing file: %s" % ref)
    print("html_check: %s px: %d images, %d links, page %d px wide"
          % (width, len(r["images"]), len(r["hrefs"]), r["scrollWidth"]))

for name in ("wide", "narrow"):
    path = os.path.join(shots, "screenshot-%s.png" % name)
    if not os.path.exists(path):
        continue
    try:
        w, h, rows = png_pixels(path)
    except (OSError, ValueError, zlib.error, KeyError) as e:
        bad.append("screenshot %s: %s" % (name, e))
        continue
    # A blank page gives the same row over and over; text and plots give many rows.
    distinct = len(set(rows))
    if distinct < 50:
        bad.append("screenshot %s looks blank: %d distinct rows of %d" % (name, distinct, h))
    print("html_check: screenshot %s %dx%d, %d distinct rows: %s" % (name, w, h, distinct, path))

for b in dict.fromkeys(bad):
    print("FAIL: " + b)
sys.exit(1 if bad else 0)
PY

if [ "$fail" = 0 ]; then
  echo "html_check: OK $page"
else
  echo "html_check: FAILED $page"
fi
exit "$fail"
