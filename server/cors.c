/* cors.c: CORS headers and preflight answers (cors.h). */
#include "cors.h"

#include <string.h>

/* 1 when origin is in the comma-separated list (exact match, spaces around items
 * ignored). */
static int listed(const char *list, const char *origin)
{
    size_t ol = strlen(origin);
    int found = 0;
    for (const char *p = list; *p && !found; p += strspn(p, ", ")) {
        size_t l = strcspn(p, ",");
        size_t t = l;
        while (t > 0 && p[t - 1] == ' ')
            t--;
        found = t == ol && !strncmp(p, origin, ol);
        p += l;
    }
    return found;
}

int td_cors_apply(const char *origins, td_http_req *q, td_http_resp *r, const char *allow)
{
    const char *origin = td_http_req_header(q, "Origin");
    const char *m = td_http_req_method(q);
    int any = origins && !strcmp(origins, "*"), preflight = 0;
    if (!origin || !origins || !*origins || (!any && !listed(origins, origin)))
        goto out;
    if (any) {
        td_http_resp_header(r, "Access-Control-Allow-Origin", "*");
    } else {
        td_http_resp_header(r, "Access-Control-Allow-Origin", "%s", origin);
        td_http_resp_header(r, "Vary", "Origin");
    }
    preflight = !strcmp(m, "OPTIONS") && td_http_req_header(q, "Access-Control-Request-Method");
    if (preflight) {
        r->status = 204;
        td_http_resp_header(r, "Access-Control-Allow-Methods", "%s", allow ? allow : "GET, HEAD");
        td_http_resp_header(r, "Access-Control-Allow-Headers", "Content-Type, If-None-Match, X-Terrad-Dataset");
        td_http_resp_header(r, "Access-Control-Max-Age", "600");
    } else {
        td_http_resp_header(r, "Access-Control-Expose-Headers",
                            "ETag, Server-Timing, X-Terrad-Method, X-Terrad-Surface, X-Terrad-Sun, X-Terrad-Rays, "
                            "X-Terrad-Steps, X-Terrad-Sun-Bound, X-Terrad-Height-Error, X-Terrad-Level, "
                            "Retry-After");
    }
out:
    return preflight;
}
