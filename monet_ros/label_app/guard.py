"""What `monet label`'s server accepts, before any route runs (no Flask here).

- Host: only the names the server was bound for (localhost, 127.0.0.1, [::1], the --host
  address and each --allow-host name, with the port) are served, so a page of another
  site whose name was rebound to this address (DNS rebinding) gets 421, never the labels;
- Origin: when a request carries one it must be one of those hosts over http (403);
- token: a request that changes state (PUT, POST, DELETE, ...) carries the per-run token
  of the page (X-Monet-Token header; the page gets it in a <meta> tag of its HTML) - a
  cookie alone would ride along with a forged request, a header set by script cannot;
- request size: MAX_CONTENT_LENGTH of request_limit.

CSP: the page's scripts, styles and images come from the server itself and no inline
script runs (a name that slipped into markup could not execute).
"""
import json

# Names that always reach this machine's loopback (and no other machine).
LOOPBACK = ('localhost', '127.0.0.1', '::1')
# Bind addresses that are no host name (every interface): names are given by --allow-host.
WILDCARD = ('', '0.0.0.0', '::')
TOKEN_HEADER = 'X-Monet-Token'
SAFE_METHODS = ('GET', 'HEAD', 'OPTIONS')
CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; "
       "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
# Floor of the request size limit: any request of a small rig and skeleton fits.
MIN_REQUEST_BYTES = 1 << 20
# Characters of the longest JSON number JavaScript writes for a coordinate
# (-1.2345678901234567e-100 style: sign, 17 digits, point, exponent).
NUMBER_CHARS = 24


def allowed_hosts(host, port, extra=()):
    """Host header values served: (localhost, 127.0.0.1, [::1], `host` unless a wildcard,
    `extra` names) x ':port' (and the bare name on port 80, as browsers send it), lower
    case, IPv6 literals in brackets (RFC 3986 section 3.2.2). frozenset of str."""
    names = {n.strip().lower().strip('[]') for n in (*LOOPBACK, host, *extra)} - set(WILDCARD)
    out = set()
    for name in names:
        literal = f'[{name}]' if ':' in name else name
        out.add(f'{literal}:{int(port)}')
        if int(port) == 80:
            out.add(literal)
    return frozenset(out)


def allowed_origins(hosts):
    """Origin header values accepted: http://HOST for each allowed Host value."""
    return frozenset(f'http://{h}' for h in hosts)


def refusal(method, host, origin, token, hosts, expected_token):
    """(status, message) of a request the server must refuse, or None to serve it.
    host / origin / token: the request's Host, Origin and X-Monet-Token values (None when
    absent); hosts: allowed_hosts(...); expected_token: the run's token."""
    import hmac

    if (host or '').lower() not in hosts:
        return 421, (f'host {host!r} is not served here (DNS rebinding guard); open '
                     f'http://{sorted(hosts)[0]}/ or start monet label with --allow-host')
    if origin is not None and origin.lower() not in allowed_origins(hosts):
        return 403, f'origin {origin!r} may not use this server (only its own pages may)'
    if method.upper() not in SAFE_METHODS and not hmac.compare_digest(
            (token or '').encode(), expected_token.encode()):
        what = 'no' if not token else 'a wrong'
        return 403, (f'{what} {TOKEN_HEADER} header: a change needs the token of a page '
                     'served by this run of monet label (reload the page)')
    return None


def request_limit(cameras, keypoints):
    """Largest request body accepted (bytes): twice the JSON of a full instant (every
    camera x keypoint labelled with the longest coordinates, plus the epipolar request's
    camera and keypoint fields), at least MIN_REQUEST_BYTES. cameras / keypoints: names."""
    number = '1' * NUMBER_CHARS
    labels = {c: {k: [number, number] for k in keypoints} for c in cameras}
    longest = max([*cameras, *keypoints], key=len, default='')
    body = json.dumps({'labels': labels, 'version': 'f' * 64, 'camera': longest,
                       'keypoint': longest}, ensure_ascii=True)
    return max(MIN_REQUEST_BYTES, 2 * len(body))
