/* fuzz_request.c: the scene parsers of server/request.c, as the HTTP service calls them
 * (the service's limits; paths not allowed). The first byte chooses: 0 mod 3 the JSON
 * scene (POST /v1/render), 1 the pick body (POST /v1/pick), 2 a query string (GET
 * /v1/render): the rest split at '&' into at most 128 key=value pairs, as the HTTP layer
 * hands them over (already decoded; a pair without '=' has an empty value). */
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "request.h"

#define QUERY_MAX 128

static void parse_query(const uint8_t *data, size_t size, const td_request_limits *lim)
{
    char *text = malloc(size + 1), *keys[QUERY_MAX], *values[QUERY_MAX], empty[1] = "";
    size_t n;
    td_scene sc;
    td_request_error re;
    if (!text)
        abort();
    memcpy(text, data, size);
    text[size] = '\0';
    n = fuzz_split_query(text, keys, values, QUERY_MAX, empty);
    fuzz_report("query", td_request_parse_query((const char *const *)keys, (const char *const *)values,
                                                n, lim, &sc, &re),
                re.message);
    free(text);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    td_request_limits lim;
    td_scene sc;
    td_request_error re;
    if (size < 1)
        return 0;
    td_request_limits_default(&lim);
    switch (data[0] % 3) {
    case 0:
        fuzz_report("scene", td_request_parse_scene((const char *)data + 1, size - 1, &lim, &sc, &re), re.message);
        break;
    case 1:
        fuzz_report("pick", td_request_parse_pick((const char *)data + 1, size - 1, &lim, &sc, &re), re.message);
        break;
    default:
        parse_query(data + 1, size - 1, &lim);
        break;
    }
    return 0;
}
