/* rlepng.c: see rlepng.h. The rows (each a filter byte 0 and its pixels) are read as one
 * stream of runs of equal bytes twice: the first pass counts the deflate symbols they
 * make (a literal where the byte changes, then copies of up to 258 bytes at distance 1,
 * a last one or two bytes as literals) and sums adler32; Huffman code lengths are made
 * from the counts (limited to 15 bits, 7 for the code-length code, RFC 1951 3.2.7); the
 * second pass writes the symbols into a buffer sized from the counts exactly. Then the
 * PNG's chunks around the zlib stream (IDATs of at most 2^30 bytes). */
#include "rlepng.h"

#include <stdlib.h>
#include <string.h>
#include <zlib.h> /* crc32 */

#define NLIT 286 /* literal/length symbols: 0..255 bytes, 256 end of block, 257..285 lengths */
#define NCL 19   /* code-length symbols */
#define IDAT_MAX ((size_t)1 << 30)

static const uint16_t len_base[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
                                      31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const uint8_t len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                      2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint8_t cl_order[NCL] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};

typedef struct rle_enc {
    int writing;          /* 0: counting (pass 1), 1: writing (pass 2) */
    int last;             /* the byte written last, -1 before the first */
    uint8_t lsym[259];    /* length L (3..258) -> its symbol's index 0..28 */
    uint64_t freq[NLIT];  /* pass 1: each symbol's count */
    uint8_t len[NLIT];    /* code lengths, 0 for symbols not used */
    uint16_t code[NLIT];  /* canonical codes, bit-reversed for the LSB-first stream */
    uint64_t s1, s2;      /* adler32's sums, reduced modulo 65521 at the end */
    uint8_t *out;         /* pass 2: the deflate stream */
    size_t n;             /* bytes written to out */
    uint64_t acc;         /* bits not yet stored, the first in bit 0 */
    int nb;
} rle_enc;

/* Appends the low n <= 32 bits of v (out has room: sized from the counts, plus 8). */
static inline void put(rle_enc *e, uint32_t v, int n)
{
    e->acc |= (uint64_t)v << e->nb;
    e->nb += n;
    if (e->nb >= 32) {
        uint32_t w = (uint32_t)e->acc;
        e->out[e->n] = (uint8_t)w;
        e->out[e->n + 1] = (uint8_t)(w >> 8);
        e->out[e->n + 2] = (uint8_t)(w >> 16);
        e->out[e->n + 3] = (uint8_t)(w >> 24);
        e->n += 4;
        e->acc >>= 32;
        e->nb -= 32;
    }
}

static inline void literal(rle_enc *e, int b)
{
    if (e->writing)
        put(e, e->code[b], e->len[b]);
    else
        e->freq[b]++;
}

/* A copy of L bytes at distance 1: its length symbol, extra bits, distance code 0 (one bit). */
static inline void copy1(rle_enc *e, size_t L)
{
    int k = e->lsym[L];
    if (e->writing) {
        put(e, e->code[257 + k], e->len[257 + k]);
        put(e, (uint32_t)(L - len_base[k]), len_extra[k]);
        put(e, 0, 1);
    } else {
        e->freq[257 + k]++;
    }
}

/* n bytes b: a literal unless the byte before was b, copies of up to 258, literals left
 * (counted at once in the first pass: n / 258 copies of 258, then the rest). */
static void put_run(rle_enc *e, int b, size_t n)
{
    if (n > 0 && e->last != b) {
        literal(e, b);
        n--;
        e->last = b;
    }
    if (!e->writing) {
        e->freq[257 + e->lsym[258]] += n / 258;
        n %= 258;
        if (n >= 3)
            e->freq[257 + e->lsym[n]]++;
        else
            e->freq[b] += n;
        n = 0;
    }
    for (size_t L; n >= 3; n -= L) {
        L = n < 258 ? n : 258;
        copy1(e, L);
    }
    for (; n > 0; n--)
        literal(e, b);
}

/* adler32's sums after n bytes v: s1 += n v, s2 += n s1 + v n (n + 1) / 2, reduced modulo
 * 65521 only when they grow large (one division a run was a third of the first pass):
 * pieces of at most 2^20 bytes keep each step's terms under 2^53. */
static void adler_run(rle_enc *e, unsigned v, size_t n)
{
    const uint64_t M = 65521, P = (uint64_t)1 << 20;
    for (uint64_t k; n > 0; n -= (size_t)k) {
        k = n < P ? n : P;
        e->s2 += k * e->s1 + v * (k * (k + 1) / 2);
        e->s1 += k * v;
        if (e->s1 >= ((uint64_t)1 << 32))
            e->s1 %= M;
        if (e->s2 >= ((uint64_t)1 << 62))
            e->s2 %= M;
    }
}

/* The length of the run of p[0] in p[0 .. n), 8 bytes at a time. */
static size_t run_len(const uint8_t *p, size_t n)
{
    uint64_t rep = 0x0101010101010101ull * p[0], x;
    size_t k = 0;
    while (k + 8 <= n) {
        memcpy(&x, p + k, 8);
        x ^= rep;
        if (x)
            return k + (size_t)__builtin_ctzll(x) / 8; /* little-endian load: byte 0 is the low one */
        k += 8;
    }
    while (k < n && p[k] == p[0])
        k++;
    return k;
}

/* One pass over the rows: each maximal run of equal bytes of the stream put_run. */
static void pass(rle_enc *e, const uint8_t *px, size_t w, int32_t h)
{
    int cur = 0;    /* the run being gathered: byte cur, run bytes (across rows) */
    size_t run = 0;
    e->last = -1;
    for (int32_t y = 0; y < h; y++) {
        const uint8_t *row = px + (size_t)y * w;
        for (size_t k = 0, n; k <= w; k += n) { /* k 0: the filter byte, then pixel k - 1 */
            int b = k ? row[k - 1] : 0;
            n = k ? run_len(row + k - 1, w - (k - 1)) : 1;
            if (b != cur) {
                put_run(e, cur, run);
                cur = b;
                run = 0;
            }
            run += n;
            if (!e->writing)
                adler_run(e, (unsigned)b, n);
        }
    }
    put_run(e, cur, run);
}

/* Huffman code lengths of at most maxbits for freq[0 .. n) (0 for unused symbols; a lone
 * symbol gets 1). Where the tree is too deep the counts are halved (kept >= 1) and the
 * tree made again: all counts 1 give a balanced tree, 9 levels for 286 symbols. */
static void huff_lengths(const uint64_t *freq, int n, int maxbits, uint8_t *len)
{
    uint64_t wt[2 * NLIT], f[NLIT];
    int parent[2 * NLIT], leaf[NLIT], m = 0, deep = 1;
    memset(len, 0, (size_t)n);
    for (int s = 0; s < n; s++)
        if (freq[s]) {
            f[m] = freq[s];
            leaf[m++] = s;
        }
    if (m == 1)
        len[leaf[0]] = 1;
    while (m > 1 && deep) {
        int nodes = m, live = m;
        char done[2 * NLIT] = {0};
        for (int i = 0; i < m; i++)
            wt[i] = f[i];
        while (live > 1) { /* join the two lightest live nodes (m is at most 286: scans are cheap) */
            int a = -1, b = -1;
            for (int i = 0; i < nodes; i++) {
                if (done[i])
                    continue;
                if (a < 0 || wt[i] < wt[a]) {
                    b = a;
                    a = i;
                } else if (b < 0 || wt[i] < wt[b]) {
                    b = i;
                }
            }
            wt[nodes] = wt[a] + wt[b];
            parent[a] = parent[b] = nodes;
            done[a] = done[b] = 1;
            nodes++;
            live--;
        }
        deep = 0;
        for (int i = 0; i < m; i++) {
            int d = 0;
            for (int j = i; j != nodes - 1; j = parent[j])
                d++;
            len[leaf[i]] = (uint8_t)d;
            deep |= d > maxbits;
        }
        for (int i = 0; i < m && deep; i++)
            f[i] = (f[i] + 1) / 2;
    }
}

/* Canonical codes (RFC 1951 3.2.2) of len[0 .. n), each bit-reversed. */
static void canon(const uint8_t *len, int n, uint16_t *code)
{
    int count[16] = {0}, next[16];
    for (int s = 0; s < n; s++)
        count[len[s]]++;
    count[0] = 0;
    for (int b = 1, c = 0; b < 16; b++) {
        c = (c + count[b - 1]) << 1;
        next[b] = c;
    }
    for (int s = 0; s < n; s++) {
        uint16_t r = 0;
        int c = len[s] ? next[len[s]]++ : 0;
        for (int k = 0; k < len[s]; k++)
            r |= (uint16_t)(((c >> k) & 1) << (len[s] - 1 - k));
        code[s] = r;
    }
}

/* The code lengths of the literal/length code and the one distance code (1 bit), in the
 * code-length alphabet: runs of zeros as 17 (3-10) or 18 (11-138), the rest literally. */
typedef struct cl_seq {
    int n, hlit;
    uint8_t sym[NLIT + 1], extra[NLIT + 1];
    uint64_t freq[NCL];
    uint8_t len[NCL];
    uint16_t code[NCL];
} cl_seq;

static void cl_build(const rle_enc *e, cl_seq *c)
{
    uint8_t all[NLIT + 1];
    int total;
    memset(c, 0, sizeof *c);
    c->hlit = NLIT;
    while (c->hlit > 257 && e->len[c->hlit - 1] == 0)
        c->hlit--;
    memcpy(all, e->len, (size_t)c->hlit);
    all[c->hlit] = 1; /* the distance code */
    total = c->hlit + 1;
    for (int i = 0, r; i < total; i += r) {
        r = 1;
        if (all[i] == 0) {
            while (i + r < total && all[i + r] == 0 && r < 138)
                r++;
            if (r >= 11) {
                c->sym[c->n] = 18;
                c->extra[c->n++] = (uint8_t)(r - 11);
                continue;
            }
            if (r >= 3) {
                c->sym[c->n] = 17;
                c->extra[c->n++] = (uint8_t)(r - 3);
                continue;
            }
            r = 1;
        }
        c->sym[c->n++] = all[i];
    }
    for (int k = 0; k < c->n; k++)
        c->freq[c->sym[k]]++;
    huff_lengths(c->freq, NCL, 7, c->len);
    canon(c->len, NCL, c->code);
}

/* Bits of the block: header, code lengths, symbols with their extra bits, end of block. */
static uint64_t block_bits(const rle_enc *e, const cl_seq *c, int ncl)
{
    static const int cl_extra[NCL] = {[16] = 2, [17] = 3, [18] = 7};
    uint64_t bits = 3 + 5 + 5 + 4 + 3 * (uint64_t)ncl;
    for (int s = 0; s < NCL; s++)
        bits += c->freq[s] * (uint64_t)(c->len[s] + cl_extra[s]);
    for (int s = 0; s < NLIT; s++)
        bits += e->freq[s] * (uint64_t)e->len[s];
    for (int k = 0; k < 29; k++)
        bits += e->freq[257 + k] * (uint64_t)(len_extra[k] + 1); /* + the distance bit */
    return bits;
}

static void write_header(rle_enc *e, const cl_seq *c, int ncl)
{
    static const int cl_extra[NCL] = {[16] = 2, [17] = 3, [18] = 7};
    put(e, 1, 1); /* the last block */
    put(e, 2, 2); /* dynamic codes */
    put(e, (uint32_t)(c->hlit - 257), 5);
    put(e, 0, 5); /* one distance code */
    put(e, (uint32_t)(ncl - 4), 4);
    for (int k = 0; k < ncl; k++)
        put(e, c->len[cl_order[k]], 3);
    for (int k = 0; k < c->n; k++) {
        put(e, c->code[c->sym[k]], c->len[c->sym[k]]);
        put(e, c->extra[k], cl_extra[c->sym[k]]);
    }
}

static void be32(uint8_t *d, uint32_t v)
{
    d[0] = (uint8_t)(v >> 24);
    d[1] = (uint8_t)(v >> 16);
    d[2] = (uint8_t)(v >> 8);
    d[3] = (uint8_t)v;
}

/* A chunk at d: length, type, the n data bytes already at d + 8, CRC; returns its size. */
static size_t chunk(uint8_t *d, const char *type, size_t n)
{
    be32(d, (uint32_t)n);
    memcpy(d + 4, type, 4);
    be32(d + 8 + n, (uint32_t)crc32(crc32(0L, Z_NULL, 0), d + 4, (uInt)(n + 4)));
    return n + 12;
}

/* The zlib stream of the rows into e->out (malloc'd, e->n bytes). */
static td_status zstream(rle_enc *e, const uint8_t *px, size_t w, int32_t h, td_err *err)
{
    td_status rc = TD_OK;
    cl_seq c;
    int ncl = NCL;
    uint64_t bytes;
    e->s1 = 1;
    e->s2 = 0;
    for (int k = 0, L = 3; k < 29; k++)
        for (; L < (k < 28 ? len_base[k + 1] : 259); L++)
            e->lsym[L] = (uint8_t)k;
    pass(e, px, w, h);
    e->freq[256] = 1; /* end of block */
    huff_lengths(e->freq, NLIT, 15, e->len);
    canon(e->len, NLIT, e->code);
    cl_build(e, &c);
    while (ncl > 4 && c.len[cl_order[ncl - 1]] == 0)
        ncl--;
    bytes = 2 + (block_bits(e, &c, ncl) + 7) / 8 + 4;
    if (bytes > SIZE_MAX - 16 || !(e->out = malloc((size_t)bytes + 8))) {
        rc = td_err_set(err, TD_ENOMEM, "image: no memory for a %llu-byte PNG stream",
                        (unsigned long long)bytes);
        goto out;
    }
    e->out[0] = 0x78; /* deflate, 32 kB window; 0x7801 % 31 == 0 */
    e->out[1] = 0x01;
    e->n = 2;
    e->writing = 1;
    write_header(e, &c, ncl);
    pass(e, px, w, h);
    put(e, e->code[256], e->len[256]);
    for (; e->nb > 0; e->nb -= 8, e->acc >>= 8) /* the bits left, to a byte */
        e->out[e->n++] = (uint8_t)e->acc;
    be32(e->out + e->n, (uint32_t)(e->s2 % 65521 << 16 | e->s1 % 65521));
    e->n += 4;
out:
    return rc;
}

td_status td_rlepng_gray8(const uint8_t *px, int32_t width, int32_t height, td_buf *out,
                          td_err *err)
{
    static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    td_status rc = TD_OK;
    rle_enc *e = NULL;
    size_t nchunks, size, at = 0;

    memset(out, 0, sizeof *out);
    if (width < 1 || height < 1 || (uint64_t)width * (uint64_t)height > SIZE_MAX / 2) {
        rc = td_err_set(err, TD_ERANGE, "image: %d x %d pixels cannot be encoded", (int)width,
                        (int)height);
        goto out;
    }
    if (!(e = calloc(1, sizeof *e))) {
        rc = td_err_set(err, TD_ENOMEM, "image: no memory for the encoder");
        goto out;
    }
    rc = zstream(e, px, (size_t)width, height, err);
    if (rc)
        goto out;
    nchunks = (e->n + IDAT_MAX - 1) / IDAT_MAX;
    size = 8 + 25 + e->n + 12 * nchunks + 12;
    if (!(out->data = malloc(size))) {
        rc = td_err_set(err, TD_ENOMEM, "image: no memory for a %zu-byte PNG", size);
        goto out;
    }
    memcpy(out->data, sig, 8);
    at = 8;
    be32(out->data + at + 8, (uint32_t)width);
    be32(out->data + at + 12, (uint32_t)height);
    memcpy(out->data + at + 16, (const uint8_t[]){8, 0, 0, 0, 0}, 5); /* 8 bits, gray, deflate, no filter, no interlace */
    at += chunk(out->data + at, "IHDR", 13);
    for (size_t k = 0; k < e->n; k += IDAT_MAX) {
        size_t n = e->n - k < IDAT_MAX ? e->n - k : IDAT_MAX;
        memcpy(out->data + at + 8, e->out + k, n);
        at += chunk(out->data + at, "IDAT", n);
    }
    at += chunk(out->data + at, "IEND", 0);
    out->len = out->cap = at;
out:
    if (e)
        free(e->out);
    free(e);
    return rc;
}
