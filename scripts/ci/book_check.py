#!/usr/bin/env python3
"""Checks the built manual (mdbook build docs -> target/book) and the README's links into it.

In every HTML page of the book, every relative link, image, stylesheet, script and frame
must name a file of the built book, and every #anchor must be an id (or name) of the page
it points at. The README's links into docs/ (written as docs/PAGE.md#anchor for readers of
the repository) must name a chapter of the book and an anchor of its built page.
External links are not followed (nothing outside the repository is linked); their count
is printed. 404.html is skipped: mdbook writes it for a web server, with its links made
absolute to the site's root.

Usage: scripts/ci/book_check.py [BOOK_DIR] [README]   (defaults: target/book, README.md)
Exit: 0 good, 1 a link or anchor is broken, 2 no built book.
Standard library only.
"""
import html.parser
import os
import re
import sys
import urllib.parse


class Page(html.parser.HTMLParser):
    """The ids of a page and the references it makes, with their tag and attribute."""

    REFS = {("a", "href"), ("img", "src"), ("link", "href"), ("script", "src"),
            ("iframe", "src"), ("source", "src")}

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids = set()
        self.refs = []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if value is None:
                continue
            if name == "id" or (tag == "a" and name == "name"):
                self.ids.add(value)
            if (tag, name) in self.REFS:
                self.refs.append((tag, value))


def parse(path, cache={}):
    if path not in cache:
        page = Page()
        with open(path, encoding="utf-8") as f:
            page.feed(f.read())
        cache[path] = page
    return cache[path]


def external(ref):
    return bool(re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", ref)) or ref.startswith("//")


def resolve(base_file, ref):
    """The file a relative reference names (index.html for a folder) and its fragment."""
    url = urllib.parse.urlsplit(ref)
    if url.path == "":
        return base_file, url.fragment
    path = os.path.normpath(os.path.join(os.path.dirname(base_file), urllib.parse.unquote(url.path)))
    if os.path.isdir(path):
        path = os.path.join(path, "index.html")
    return path, url.fragment


def main():
    book = sys.argv[1] if len(sys.argv) > 1 else "target/book"
    readme = sys.argv[2] if len(sys.argv) > 2 else "README.md"
    if not os.path.isfile(os.path.join(book, "index.html")):
        print("book_check: no built book in %s (run mdbook build docs)" % book)
        return 2
    book = os.path.abspath(book)
    bad, pages, checked, outside = [], 0, 0, 0
    for folder, _, files in os.walk(book):
        for name in sorted(files):
            if not name.endswith(".html") or (folder == book and name == "404.html"):
                continue
            path = os.path.join(folder, name)
            pages += 1
            for tag, ref in parse(path).refs:
                if external(ref):
                    outside += 1
                    continue
                target, fragment = resolve(path, ref)
                checked += 1
                rel = os.path.relpath(path, book)
                if not target.startswith(book + os.sep):
                    bad.append("%s: <%s> %s leaves the book" % (rel, tag, ref))
                elif not os.path.isfile(target):
                    bad.append("%s: <%s> %s: no such file" % (rel, tag, ref))
                elif fragment and target.endswith(".html") and fragment not in parse(target).ids:
                    bad.append("%s: <%s> %s: no anchor #%s" % (rel, tag, ref, fragment))
    # The README's links into the manual, checked against the built pages.
    readme_links = 0
    text = open(readme, encoding="utf-8").read()
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    for ref in re.findall(r"\]\(([^)\s]+)\)", text):
        if not ref.startswith("docs/") or external(ref):
            continue
        readme_links += 1
        url = urllib.parse.urlsplit(ref)
        chapter = url.path[len("docs/"):]
        if chapter == "SUMMARY.md":
            continue
        built = os.path.join(book, re.sub(r"\.md$", ".html", chapter))
        if not os.path.isfile(built):
            bad.append("%s: %s is not a chapter of the book (no %s)" % (readme, ref, os.path.relpath(built, book)))
        elif url.fragment and url.fragment not in parse(built).ids:
            bad.append("%s: %s: no anchor #%s in the built page" % (readme, ref, url.fragment))
    print("book_check: %d pages, %d relative references checked, %d external not followed, "
          "%d README links into the manual" % (pages, checked, outside, readme_links))
    for b in dict.fromkeys(bad):
        print("FAIL: " + b)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
