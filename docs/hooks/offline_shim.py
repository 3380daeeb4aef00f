"""MkDocs hook: the material theme's offline search without a CDN.

For its search on file:// pages, the theme's ``offline`` plugin loads a WebWorker shim (npm's ``iframe-worker``)
from unpkg. The site carries that shim itself (``docs/javascripts/iframe-worker-shim.js``, 1.4 kB, MIT), and each
page loads it from there: the site needs no network.
"""

from mkdocs.utils import get_relative_url

CDN = "https://unpkg.com/iframe-worker/shim"
LOCAL = "javascripts/iframe-worker-shim.js"


def on_post_page(output: str, page, config) -> str:
    return output.replace(f'"{CDN}"', f'"{get_relative_url(LOCAL, page.url)}"')


def on_post_template(output: str, template_name: str, config) -> str:
    return output.replace(f'"{CDN}"', f'"{LOCAL}"')  # 404.html, at the site's root
