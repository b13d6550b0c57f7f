/* mhdapi.h: libmicrohttpd's API through a table loaded on first use (core/dynlib.h), not
 * linked in: only `terrad serve` needs it, and linking it made every command (render,
 * viewshed, trace, info) pay 3.3 ms of start-up for it and the TLS stack it brings
 * (dynlib.h). http.c, its one user, includes this header instead of <microhttpd.h>: it
 * includes that header for the types and constants and turns each function it calls into
 * the table's entry, so the code reads as libmicrohttpd's own. td_http_start calls
 * td_mhd_open first, which loads the library once and refuses with TD_EUNSUPPORTED,
 * naming it and dlerror's reason, when it cannot. The library's name is the soname CMake
 * found (TERRAD_MHD_SONAME). A function added to http.c must be added to TD_MHD_FNS and
 * given its #define below. */
#ifndef TD_MHDAPI_H
#define TD_MHDAPI_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>
#include <sys/types.h>

#include <microhttpd.h>

#include "status.h"

/* Loads libmicrohttpd once; TD_OK when the table is ready, else TD_EUNSUPPORTED with the
 * reason in err (every call gives the same). */
td_status td_mhd_open(td_err *err);

#define TD_MHD_FNS(X)                                                                              \
    X(MHD_add_response_header) X(MHD_create_response_from_buffer)                                  \
    X(MHD_create_response_from_buffer_with_free_callback) X(MHD_destroy_response)                  \
    X(MHD_get_connection_values) X(MHD_get_daemon_info) X(MHD_lookup_connection_value)             \
    X(MHD_queue_response) X(MHD_quiesce_daemon) X(MHD_resume_connection) X(MHD_start_daemon)       \
    X(MHD_stop_daemon) X(MHD_suspend_connection)

#define TD_MHD_MEMBER(f) __typeof__(f) *f;
typedef struct td_mhd_api {
    TD_MHD_FNS(TD_MHD_MEMBER)
} td_mhd_api;
#undef TD_MHD_MEMBER

/* Filled by td_mhd_open; read only after it returned TD_OK. */
extern td_mhd_api td_mhd;

#ifndef TD_MHDAPI_IMPL /* mhdapi.c names the real functions to take their types */
#define MHD_add_response_header (td_mhd.MHD_add_response_header)
#define MHD_create_response_from_buffer (td_mhd.MHD_create_response_from_buffer)
#define MHD_create_response_from_buffer_with_free_callback                                         \
    (td_mhd.MHD_create_response_from_buffer_with_free_callback)
#define MHD_destroy_response (td_mhd.MHD_destroy_response)
#define MHD_get_connection_values (td_mhd.MHD_get_connection_values)
#define MHD_get_daemon_info (td_mhd.MHD_get_daemon_info)
#define MHD_lookup_connection_value (td_mhd.MHD_lookup_connection_value)
#define MHD_queue_response (td_mhd.MHD_queue_response)
#define MHD_quiesce_daemon (td_mhd.MHD_quiesce_daemon)
#define MHD_resume_connection (td_mhd.MHD_resume_connection)
#define MHD_start_daemon (td_mhd.MHD_start_daemon)
#define MHD_stop_daemon (td_mhd.MHD_stop_daemon)
#define MHD_suspend_connection (td_mhd.MHD_suspend_connection)
#endif

#endif
