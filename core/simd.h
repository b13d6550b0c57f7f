/* simd.h: how terrad's row loops get wide registers without giving up the baseline.
 * Included by the files whose loops run over whole rows (edt.c, planes.c, camera.c). */
#ifndef TD_SIMD_H
#define TD_SIMD_H

/* Row loops that vectorise (the distance transform's, the planes', the camera's rays). On
 * x86-64 their functions are built three times (put TD_ROW_CLONES on the definition), for
 * the baseline (SSE2), for AVX2 and for AVX-512 (x86-64-v4), and the loader picks the one
 * the processor runs (GCC/clang function multiversioning): AVX2 is twice the width, 35%
 * fewer instructions for the planes of trinidad; the AVX-512 clone (2026-12-02, its masks
 * and 32 registers; GCC keeps loops it vectorises at 256 bits) took trinidad's max-mipmaps
 * and planes from 85.5 to 81.3 ms (median of 5, one thread, interleaved) and the
 * viewshed's max-mipmaps from 5.8 to 4.8 ms. Never FMA (-ffp-contract=off: the ISA has it,
 * the build contracts nothing), so all give the same results bit for bit. */
#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define TD_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define TD_SANITIZED 1
#endif
/* Not under a sanitizer: the loader runs the resolvers before the sanitizer's runtime is
 * up, and their instrumentation crashes (seen with ThreadSanitizer). */
#if defined(__x86_64__) && defined(__has_attribute) && !defined(TD_SANITIZED)
#if __has_attribute(target_clones) && defined(__ELF__)
#define TD_ROW_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
/* The ray packets (trace.c's fan_packet and occ_packets) and the max-mipmap walk
 * (hier_run: `terrad trace` of oblique rays 55.7 -> 54.0 ms, picos's rolled view's primary
 * stage 37.3 -> 36.7 ms; the cell test and the other methods' walks were no faster as
 * clones, whose calls go through the loader's indirection), built a third time for AVX-512
 * (x86-64-v4): the same four-lane code, with 32 vector registers instead of 16 (a third of
 * the AVX2 clone's instructions are spills) and mask registers for its selects. Still no
 * FMA (-ffp-contract=off), so every clone gives the same bits. Measured on the AMD EPYC
 * the benchmarks run on (median of 7, chrt): primary stage 12.04 -> 11.52 ms on trinidad's
 * level view, 23.21 -> 22.10 straight down, 19.76 -> 18.91 rolled; shadows stage 5.40 ->
 * 5.04 level, 11.98 -> 11.43 grazing, 18.23 -> 17.09 straight down. The tests run the clone
 * the machine picks (valgrind reports no AVX-512, so callgrind counts the AVX2 one; the
 * sanitizer builds the baseline's). */
#define TD_PACKET_CLONES __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif
#endif
#ifndef TD_ROW_CLONES
#define TD_ROW_CLONES
#endif
#ifndef TD_PACKET_CLONES
#define TD_PACKET_CLONES
#endif
/* The packets again, eight lanes wide, for processors with AVX-512 (trace.c includes
 * trace_lanes.inc a second time under #pragma GCC target("arch=x86-64-v4") and picks that
 * instance at run time, td_trace_lanes; on such a processor it runs instead of the clone
 * above): GCC on x86-64 only (clang ignores the pragma, and would build the eight lanes for
 * the baseline), sanitizers included (no loader resolver: the pick is a plain call, so the
 * sanitizer builds test the eight lanes too). Against four lanes on the same EPYC
 * (interleaved, best of 9 renders): camera rays of the bench's pitched views 1.07-1.19x
 * faster, shadow rays 1.02-1.21x (README, "Coherent camera and shadow rays"). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define TD_PACKET_WIDE 1
#else
#define TD_PACKET_WIDE 0
#endif

#endif
