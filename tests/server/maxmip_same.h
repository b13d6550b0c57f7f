/* maxmip_same.h: the store's tests' check that a max-mipmap read back from the disk cache
 * (or kept resident) equals a fresh td_maxmip_build: codes, their scale, and the 4 x 4
 * blocks' minima the sun bound's shadow side reads. Include after cmocka.h. */
#ifndef TD_MAXMIP_SAME_H
#define TD_MAXMIP_SAME_H

#include "maxmip.h"

static inline void same_maxmip(const td_maxmip *a, const td_maxmip *m)
{
    size_t codes = m->offset[m->levels] + (size_t)m->dim[m->levels] * (size_t)m->dim[m->levels];
    assert_int_equal(a->bytes, m->bytes);
    assert_int_equal(a->levels, m->levels);
    assert_memory_equal(a->code, m->code, codes * sizeof *m->code);
    assert_true(a->base == m->base && a->step == m->step);
    assert_int_equal(a->min4_w, m->min4_w);
    assert_int_equal(a->min4_h, m->min4_h);
    assert_memory_equal(a->min4, m->min4, (size_t)m->min4_w * (size_t)m->min4_h * sizeof *m->min4);
}

#endif
