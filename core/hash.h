/* hash.h: FNV-1a, 64 bits: the one byte hash of terrad. The server's ETags of renders
 * and map tiles (server/routes.c) and the tile store's dataset fingerprints and cache
 * file checksums (server/tilestore.c) read it. Fast and well spread, not keyed: nothing
 * may rely on it against input chosen to collide.
 *
 * Chained: td_fnv1a(td_fnv1a(TD_FNV1A_INIT, a, na), b, nb) hashes a then b, the same as
 * one call over the two buffers laid end to end. */
#ifndef TD_HASH_H
#define TD_HASH_H

#include <stddef.h>
#include <stdint.h>

#define TD_FNV1A_INIT 14695981039346656037ULL /* the offset basis */
#define TD_FNV1A_PRIME 1099511628211ULL

/* h folded with the n bytes at data (byte by byte: xor, then times the prime). */
uint64_t td_fnv1a(uint64_t h, const void *data, size_t n);

#endif
