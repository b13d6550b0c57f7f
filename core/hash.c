/* hash.c: FNV-1a, 64 bits (see hash.h). */
#include "hash.h"

uint64_t td_fnv1a(uint64_t h, const void *data, size_t n)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < n; i++) {
        h ^= p[i];
        h *= TD_FNV1A_PRIME;
    }
    return h;
}
