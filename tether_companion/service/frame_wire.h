/* The MAVLink 2 input frame's wire test and field bits, shared by the extension's two files:
 * frame_core.c (take, fields, the module) and frame_reader.c (Reader, the checked samples).
 * Static inline functions of one extension; frame_core.c's header comment says what the test
 * is and what the spec bytes hold.
 */
#ifndef TETHER_FRAME_WIRE_H
#define TETHER_FRAME_WIRE_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#define HEADER_V2 10
#define STX_V2 0xFD
#define MAX_PAYLOAD 255

/* The spec's entry of `msg_id` (a pointer to its crc_extra byte) or NULL; checks the spec's
 * bounds as it walks it (a malformed spec is a ValueError: *bad = 1). */
static inline const unsigned char *
find_entry(const unsigned char *spec, Py_ssize_t spec_len, uint32_t msg_id, int *bad)
{
    Py_ssize_t pos = 3;
    int entries = spec[2];
    for (int e = 0; e < entries; e++) {
        if (pos + 8 > spec_len) {
            *bad = 1;
            return NULL;
        }
        const unsigned char *p = spec + pos;
        uint32_t id = (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
                      | ((uint32_t)p[3] << 24);
        Py_ssize_t next = pos + 8 + 2 * (Py_ssize_t)p[7];
        if (next > spec_len) {
            *bad = 1;
            return NULL;
        }
        if (id == msg_id)
            return p + 4;
        pos = next;
    }
    return NULL;
}

/* MAVLink's X.25 checksum (MCRF4XX) of `n` bytes, continuing `crc`. */
static inline uint16_t
crc_accumulate(const unsigned char *data, Py_ssize_t n, uint16_t crc)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        uint8_t tmp = data[i] ^ (uint8_t)(crc & 0xFF);
        tmp ^= (uint8_t)(tmp << 4);
        crc = (uint16_t)((crc >> 8) ^ ((uint16_t)tmp << 8) ^ ((uint16_t)tmp << 3) ^ (tmp >> 4));
    }
    return crc;
}

/* The entry (from its crc_extra byte: crc_extra, size, code, field count, fields) when `f`
 * (`n` bytes) is a frame the table takes, else NULL; *bad = 1 for a malformed spec. */
static inline const unsigned char *
taken(const unsigned char *spec, Py_ssize_t spec_len, const unsigned char *f, Py_ssize_t n,
      int *bad)
{
    if (spec_len < 3) {
        *bad = 1;
        return NULL;
    }
    if (n <= HEADER_V2 || f[0] != STX_V2 || f[2] != 0)
        return NULL;
    uint32_t msg_id = (uint32_t)f[7] | ((uint32_t)f[8] << 8) | ((uint32_t)f[9] << 16);
    const unsigned char *entry = find_entry(spec, spec_len, msg_id, bad);
    if (entry == NULL || f[5] != spec[0] || f[6] != spec[1])
        return NULL;
    Py_ssize_t end = n - 2;
    if (end != HEADER_V2 + (Py_ssize_t)f[1] || f[1] > entry[1])
        return NULL;
    uint16_t crc = crc_accumulate(f + 1, end - 1, 0xFFFF);
    crc = crc_accumulate(entry, 1, crc);
    if (crc != ((uint16_t)f[end] | ((uint16_t)f[end + 1] << 8)))
        return NULL;
    return entry;
}

/* A ValueError for a spec the walk found malformed; NULL. */
static inline PyObject *
malformed(void)
{
    PyErr_SetString(PyExc_ValueError, "malformed frame spec");
    return NULL;
}

/* The unsigned bits of the field at `offset` (struct format `type`, one of QqIiHhBbfd) of the
 * payload `p` whose first `length` bytes were sent; bytes past `length` read as zero. */
static inline uint64_t
field_bits(const unsigned char *p, int length, int offset, int type)
{
    int size = (type == 'Q' || type == 'q' || type == 'd') ? 8
               : (type == 'I' || type == 'i' || type == 'f') ? 4
               : (type == 'H' || type == 'h') ? 2 : 1;
    uint64_t u = 0;
    for (int i = size - 1; i >= 0; i--)
        u = (u << 8) | (offset + i < length ? p[offset + i] : 0);
    return u;
}

/* Readies the Reader type and adds it to the module `m` (frame_reader.c); 0 with an error set. */
int tether_frame_reader_add(PyObject *m);
/* Whether `o` is a Reader; a Reader's read(frame) (frame_reader.c). */
int tether_is_reader(PyObject *o);
PyObject *tether_reader_read(PyObject *reader, PyObject *frame);
/* Readies the IngestCore type and adds it to `m` (ingest_core.c); 0 with an error set. */
int tether_ingest_core_add(PyObject *m);

#endif
