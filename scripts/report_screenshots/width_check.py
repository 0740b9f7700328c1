#!/usr/bin/env python3
"""Helpers of run.sh: the in-browser width check and the screenshot's shrinking.

  width_check.py inject PAGE COPY      COPY = PAGE with the measuring script added
  width_check.py verdict DOM NAME      reads what the script wrote into the dumped DOM; exit 1 if
                                       anything scrolls sideways or sticks out at the window width
  width_check.py shrink PNG OUT        OUT = PNG as a palette PNG under 400 KB
"""

import json
import os
import re
import sys

# Runs after everything (plots, pictures) has loaded: the page's own width against the window,
# every element that scrolls sideways (scroll width beyond its box, overflow not visible), and
# every table, picture, plot or figure whose right edge lies past the window's.
SCRIPT = """<script>
addEventListener('load', () => {
  const root = document.documentElement, width = root.clientWidth, bad = [];
  const name = e => e.tagName.toLowerCase() + (e.id ? '#' + e.id : '') +
    (e.className ? '.' + String(e.className).replace(/ /g, '.') : '');
  for (const e of document.querySelectorAll('body *')) {
    const s = getComputedStyle(e);
    if (s.overflowX !== 'visible' && e.scrollWidth > e.clientWidth + 1)
      bad.push(name(e) + ' scrolls: ' + e.scrollWidth + ' > ' + e.clientWidth);
  }
  for (const e of document.querySelectorAll('table, img, figure, svg, pre, code, h1, p')) {
    const r = e.getBoundingClientRect();
    if (r.width > 0 && r.right > width + 0.5)
      bad.push(name(e) + ' ends at ' + Math.round(r.right) + ' px');
  }
  const out = document.createElement('pre');
  out.id = 'width-check';
  out.textContent = JSON.stringify({window: innerWidth, client: width,
    scroll: root.scrollWidth, body: document.body.scrollWidth, bad: bad.slice(0, 20)});
  document.body.appendChild(out);
});
</script>"""

LIMIT = 400 * 1024


def inject(page, copy):
    html = open(page, encoding="utf-8").read()
    at = html.rfind("</body>")
    if at < 0:
        at = html.rfind("</html>")
    html = html + SCRIPT if at < 0 else html[:at] + SCRIPT + html[at:]
    open(copy, "w", encoding="utf-8").write(html)


def verdict(dom, name):
    text = open(dom, encoding="utf-8").read()
    m = re.search(r'<pre id="width-check">(.*?)</pre>', text, re.S)
    if not m:
        print(f"{name}: the width check did not run (no result in the DOM)")
        return 1
    r = json.loads(m.group(1).replace("&quot;", '"').replace("&gt;", ">").replace("&lt;", "<").replace("&amp;", "&"))
    ok = r["scroll"] <= r["client"] and r["body"] <= r["client"] and not r["bad"]
    print(f"{name}: window {r['window']} px, page {r['scroll']} px wide: "
          + ("no horizontal scroll" if ok else "SCROLLS SIDEWAYS"))
    for b in r["bad"]:
        print(f"  {b}")
    return 0 if ok else 1


def shrink(png, out):
    from PIL import Image

    img = Image.open(png).convert("RGB")
    # Drop the blank bottom of a page shorter than the window.
    bbox = Image.eval(img, lambda v: 255 - v).getbbox()
    if bbox:
        img = img.crop((0, 0, img.width, min(img.height, bbox[3] + 16)))
    colours = 256
    while True:
        # Octree keeps the rare saturated colours (legend markers, outlines) that median cut
        # merges into their neighbours.
        img.quantize(colors=colours, method=Image.Quantize.FASTOCTREE).save(out, optimize=True)
        size = os.path.getsize(out)
        if size < LIMIT or img.height < 400:
            break
        if colours > 64:
            colours //= 2
        else:
            img = img.crop((0, 0, img.width, int(img.height * 0.8)))
    print(f"  {out}: {img.width} × {img.height}, {size // 1024} KB")


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "inject":
        inject(*args)
    elif cmd == "verdict":
        sys.exit(verdict(*args))
    elif cmd == "shrink":
        shrink(*args)
    else:
        sys.exit(f"unknown command {cmd}")
