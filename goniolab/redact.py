"""Passwords out of every message, log line, repr and stored snapshot, by *parsing*.

Two forms of a PostgreSQL connection string carry a password (PostgreSQL manual,
"libpq - Connection Strings", sec. 34.1.1):

* the URI ``postgresql://user:password@host:port/db?...``: the userinfo ends at the
  ``@`` before the host. A password typed with a raw ``@``, ``/`` or a space (not
  percent-encoded) is still blanked: the userinfo is taken up to the *last* ``@`` of the
  URI, and a ``user:`` whose URI has no ``@`` before a space is followed to the next ``@``
  on the same line;
* the keyword/value string ``host=h password=secret dbname=d``: a value is a single-quoted
  string (backslash escapes ``\\'`` and ``\\\\``) or runs to the next whitespace.

Nothing is replaced by its *value*: an environment variable (``PGPASSWORD``) is never
searched for as plain text (that turned ``configs/lab-sim.toml`` into ``configs/***-sim.toml``
for ``PGPASSWORD=lab`` and revealed the password by the holes it left). Messages that libpq
builds from a password it could not parse (``invalid percent-encoded token: "..."``) are
withheld whole by :func:`scrub_driver_message`, which knows the password by parsing the
connection string it was given.

Every function here runs in time linear in the length of the text (tested on megabytes).
"""

from __future__ import annotations

import re
from urllib.parse import unquote

__all__ = [
    "MASK",
    "conninfo_password",
    "is_conninfo",
    "redact",
    "redact_obj",
    "scrub_driver_message",
]

MASK = "***"

#: libpq connection keywords (manual sec. 34.1.2) that mark a keyword/value string.
_KEYWORDS = (
    "host",
    "hostaddr",
    "port",
    "dbname",
    "user",
    "password",
    "passfile",
    "service",
    "sslmode",
    "sslrootcert",
    "sslcert",
    "sslkey",
    "connect_timeout",
    "options",
    "application_name",
    "target_session_attrs",
)
_CONNINFO_START = re.compile(r"\s*(?:" + "|".join(_KEYWORDS) + r")\s*=", re.I)
#: ``password = value`` of a keyword/value string: quoted (escapes allowed, an unterminated
#: quote runs to the end) or up to whitespace. Each alternative consumes distinct
#: characters, so the search is linear.
_KV_PASSWORD = re.compile(r"(password\s*=\s*)('(?:[^'\\]|\\.)*(?:'|\\?$)|[^\s']\S*|)", re.I)
_SCHEME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789+.-")
#: Characters that end a URI written in running text.
_URI_END = re.compile(r"[\s'\"<>`]")


def is_conninfo(text: str) -> bool:
    """Whether ``text`` is a libpq keyword/value connection string (``host=... dbname=...``)."""
    return bool(_CONNINFO_START.match(text))


def _redact_uris(text: str) -> str:
    """Blank the password of every ``scheme://user:password@`` in ``text`` (linear time)."""
    out: list[str] = []
    pos = 0  # text[:pos] is already in ``out``
    search = 0
    n = len(text)
    # cached look-aheads (each re-searched only once passed, so the scan stays linear):
    next_at = -2  # the next '@' (-1: none left)
    next_nl = -2  # the next newline (-1: none left)
    while True:
        sep = text.find("://", search)
        if sep < 0:
            break
        start = sep + 3
        # the scheme: letters, digits, + . - back to a letter
        k = sep
        while k > 0 and text[k - 1] in _SCHEME_CHARS:
            k -= 1
        if k == sep or not text[k].isalpha():
            search = start
            continue
        m = _URI_END.search(text, start)
        end = n if m is None else m.start()
        at = text.rfind("@", start, end)
        colon = text.find(":", start, at if at >= 0 else end)
        # "user:@pass word@host": an '@' and a raw space in the password; the '@' found
        # is the password's own when a space cut the URI and no path follows it (a host
        # with a path, "host:5432/runs", is a URI's end): follow to the next '@' too
        own_at = (
            at >= 0 and 0 <= colon < at and m is not None and text[m.start()] == " "
            and "/" not in text[at + 1 : end]
        )  # fmt: skip
        if (at < 0 and colon >= 0) or own_at:
            # "user:pass word@host": a raw space in the password; follow to the next '@'
            # on the line, unless what follows the colon is a port with a path after it
            # ("host:5432/db"; a bare "host:5432" is followed too: safe rather than sorry)
            rest = text[colon + 1 : end]
            after = rest.split("/", 1)[0]
            port = after.isdigit() and "/" in rest
            if own_at or (after and not port and text[start] != "["):
                if next_at != -1 and next_at < end:
                    next_at = text.find("@", end)
                if next_nl != -1 and next_nl < end:
                    next_nl = text.find("\n", end)
                line_end = n if next_nl < 0 else next_nl
                if 0 <= next_at < line_end:
                    at = next_at
                    m = _URI_END.search(text, at)
                    end = n if m is None else m.start()
        if at >= 0 and 0 <= colon < at:
            out.append(text[pos : colon + 1])
            out.append(MASK)
            pos = at
        search = max(end, start)
    out.append(text[pos:])
    return "".join(out)


def redact(text: str) -> str:
    """``text`` with every connection-string password replaced by ``***``.

    Parameters
    ----------
    text
        Any message: a URI, a keyword/value string, a log line, a traceback.

    Returns
    -------
    str
        The same text with the password of each ``scheme://user:password@`` and each
        ``password=value`` blanked; nothing else changes.
    """
    if "://" in text:
        text = _redact_uris(text)
    if "assword" in text or "ASSWORD" in text:
        text = _KV_PASSWORD.sub(lambda m: m.group(1) + MASK, text)
    return text


def redact_obj(obj: object) -> object:
    """``obj`` (JSON-like: dicts, lists, strings) with :func:`redact` applied to every string."""
    if isinstance(obj, str):
        return redact(obj)
    if isinstance(obj, dict):
        return {k: redact_obj(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [redact_obj(v) for v in obj]
    return obj


def _kv_value(text: str, i: int) -> tuple[str, int]:
    """The value starting at ``text[i]`` of a keyword/value string and the index after it."""
    if i < len(text) and text[i] == "'":
        buf: list[str] = []
        i += 1
        while i < len(text) and text[i] != "'":
            if text[i] == "\\" and i + 1 < len(text):
                i += 1
            buf.append(text[i])
            i += 1
        return "".join(buf), i + 1
    j = i
    while j < len(text) and not text[j].isspace():
        j += 1
    return text[i:j], j


def _is_uri(conninfo: str) -> bool:
    """Whether ``conninfo`` is a URI: a string that starts with a libpq keyword is a
    keyword/value string whatever its values hold (``password='0://'``: manual sec.
    34.1.1), else one with ``://`` is a URI."""
    return "://" in conninfo and not is_conninfo(conninfo)


def conninfo_password(conninfo: str) -> str | None:
    """The password a connection string carries (percent-decoded for a URI), else ``None``."""
    if _is_uri(conninfo):
        head = conninfo.split("://", 1)[1]
        m = _URI_END.search(head)
        token = head if m is None else head[: m.start()]
        at = token.rfind("@")
        if at < 0 or ":" not in token[:at]:
            return None
        raw = token[:at].split(":", 1)[1]
        return unquote(raw) if "%" in raw else raw
    m = _KV_PASSWORD.search(conninfo)
    if m is None:
        return None
    value, _ = _kv_value(conninfo, m.start(2))
    return value


def scrub_driver_message(message: str, conninfo: str) -> str:
    """A database driver's message made safe to show: :func:`redact`, and withheld whole
    when it quotes the password (or a piece of it) or a connection string it could not
    parse (libpq quotes the offending token, which may be part of the password).

    The password is known by parsing ``conninfo`` (never from the environment); a message
    is withheld rather than patched so that no hole reveals the secret's length or place.
    """
    plain = " ".join(message.split())
    text = redact(plain)
    secret = conninfo_password(conninfo)
    if secret is None:
        return text
    uri = _is_uri(conninfo)
    raw = conninfo.split("://", 1)[1] if uri else conninfo
    pieces = {secret, *secret.split()}
    if uri and "%" in raw:
        at = raw.rfind("@")
        if at >= 0 and ":" in raw[:at]:
            pieces.add(raw[:at].split(":", 1)[1])
    parse_error = any(
        w in text
        for w in ("percent-encoded", "connection info string", "invalid URI", "invalid integer")
    )
    # looked for before redact(): a password that reads as a URI ("a://u:p@h") would be
    # half-blanked by it, and the half left would show
    if parse_error or any(len(p) >= 2 and p in plain for p in pieces):
        return (
            "the driver's message is withheld: it quotes the connection string, which holds a "
            "password (check the URL: percent-encode '@', '/', ':', '%' and spaces in the "
            "password, or give it through PGPASSWORD or ~/.pgpass)"
        )
    return text
