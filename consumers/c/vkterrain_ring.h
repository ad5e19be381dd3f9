/*
 * vkterrain_ring.h: read frames from a vkterrain shared-memory ring (layout version 1).
 * Single header, C11, Linux. See docs/ring.md for the protocol; a test compiles this file
 * and checks every offset below against the Rust layout (src/output/ring/layout.rs).
 *
 *   vkt_ring r;
 *   if (vkt_ring_open(&r, "vkterrain") != 0) ...;          // read-only mapping
 *   vkt_frame_meta m;
 *   int ev = vkt_ring_wait_next(&r, 1000, &m, buf, bufsize); // VKT_FRAME, VKT_TIMEOUT, ...
 *   vkt_ring_close(&r);
 *
 * Seqlock: a slot's `seq` is 2*frame+1 while the producer writes it and 2*frame+2 once complete.
 * A reader loads seq (acquire), copies, issues an acquire fence and re-loads seq; the copy is
 * accepted only if both loads are equal and even. Correct on aarch64 and x86 alike.
 */
#ifndef VKTERRAIN_RING_H
#define VKTERRAIN_RING_H

#include <stdint.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include <errno.h>
#include <fcntl.h>
#include <time.h>
#include <unistd.h>
#include <stdatomic.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <linux/futex.h>

#define VKT_MAGIC 0x31474E4952544B56ull /* "VKTRING1" little-endian */
#define VKT_LAYOUT_VERSION 1u
#define VKT_FORMAT_RGBA8_SRGB 1u
#define VKT_DEPTH_NONE 0u
#define VKT_DEPTH_F32_REVERSED_Z 1u
#define VKT_STATE_LIVE 1u
#define VKT_STATE_CLOSED 2u
#define VKT_STATE_REPLACED 3u
#define VKT_NO_FRAME UINT64_MAX

typedef struct vkt_ring_header {
    /* line 0: written once before the segment gets its name */
    uint64_t magic;            /*   0 */
    uint32_t layout_version;   /*   8 */
    uint32_t header_size;      /*  12 */
    uint64_t generation;       /*  16 */
    uint32_t width;            /*  24 */
    uint32_t height;           /*  28 */
    uint32_t pixel_format;     /*  32 */
    uint32_t row_stride;       /*  36 */
    uint32_t slot_count;       /*  40 */
    uint32_t depth_format;     /*  44 */
    uint32_t slot_size;        /*  48 */
    uint32_t pixels_offset;    /*  52 */
    uint32_t depth_offset;     /*  56 */
    uint32_t producer_pid;     /*  60 */
    /* line 1 */
    _Atomic uint64_t latest;   /*  64: newest published frame, VKT_NO_FRAME before the first */
    _Atomic uint32_t state;    /*  72 */
    uint8_t _pad1[52];
    /* line 2 */
    _Atomic uint32_t wake;     /* 128: futex word, +1 per publish and on close */
    uint8_t _pad2[60];
    /* line 3 */
    _Atomic uint64_t published;/* 192 */
    uint8_t _pad3[56];
} vkt_ring_header;             /* 256 bytes */

typedef struct vkt_frame_meta {
    uint64_t frame;            /*   0 */
    uint64_t capture_ns;       /*   8: CLOCK_MONOTONIC, readback complete */
    uint64_t publish_ns;       /*  16: CLOCK_MONOTONIC, slot complete */
    uint32_t width;            /*  24 */
    uint32_t height;           /*  28 */
    uint32_t row_stride;       /*  32 */
    uint32_t _reserved0;       /*  36 */
    double position[3];        /*  40: metres, x east, y north, z up */
    double yaw_deg;            /*  64 */
    double pitch_deg;          /*  72 */
    double roll_deg;           /*  80 */
    double vfov_deg;           /*  88 */
    double near_m;             /*  96 */
    double far_m;              /* 104 */
    double fx, fy, cx, cy;     /* 112..144: pinhole intrinsics, pixels */
    double gpu_prepass_ms;     /* 144 */
    double gpu_terrain_ms;     /* 152 */
    double gpu_readback_ms;    /* 160 */
    double cpu_record_ms;      /* 168 */
    double cpu_wait_ms;        /* 176 */
    uint64_t triangles;        /* 184 */
} vkt_frame_meta;              /* 192 bytes */

typedef struct vkt_slot_header {
    _Atomic uint64_t seq;      /*   0: seqlock */
    uint8_t _pad0[56];
    vkt_frame_meta meta;       /*  64 */
} vkt_slot_header;             /* 256 bytes; pixels follow at pixels_offset */

_Static_assert(sizeof(vkt_ring_header) == 256, "ring header size");
_Static_assert(sizeof(vkt_slot_header) == 256, "slot header size");
_Static_assert(sizeof(vkt_frame_meta) == 192, "frame meta size");

enum { VKT_FRAME = 0, VKT_TIMEOUT = 1, VKT_CLOSED = 2, VKT_RESTARTED = 3, VKT_ERROR = -1 };

typedef struct vkt_ring {
    char name[256];
    int fd;
    const uint8_t *base;
    size_t size;
    uint64_t generation;
    uint64_t last;        /* last frame returned, VKT_NO_FRAME before the first */
    uint64_t received, lost, torn_retries, restarts;
} vkt_ring;

static inline const vkt_ring_header *vkt_header(const vkt_ring *r) {
    return (const vkt_ring_header *)r->base;
}

static inline int vkt__name_ok(const char *name) {
    size_t n = strlen(name);
    if (n < 1 || n > 200 || name[0] == '.') return 0;
    for (size_t i = 0; i < n; i++) {
        char c = name[i];
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              c == '.' || c == '_' || c == '-'))
            return 0;
    }
    return 1;
}

/* Opens /dev/shm/<name> read-only and checks the header. 0 on success, -1 with errno set. */
static inline int vkt_ring_open(vkt_ring *r, const char *name) {
    memset(r, 0, sizeof *r);
    r->fd = -1;
    r->last = VKT_NO_FRAME;
    if (!vkt__name_ok(name)) { errno = EINVAL; return -1; }
    strcpy(r->name, name);
    char path[260];
    path[0] = '/';
    strcpy(path + 1, name);
    int fd = shm_open(path, O_RDONLY | O_CLOEXEC, 0);
    if (fd < 0) return -1;
    struct stat st;
    if (fstat(fd, &st) != 0 || (size_t)st.st_size < sizeof(vkt_ring_header)) {
        close(fd); errno = EPROTO; return -1;
    }
    void *p = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_SHARED, fd, 0);
    if (p == MAP_FAILED) { close(fd); return -1; }
    const vkt_ring_header *h = (const vkt_ring_header *)p;
    uint64_t need = (uint64_t)h->header_size + (uint64_t)h->slot_size * h->slot_count;
    if (h->magic != VKT_MAGIC || h->layout_version != VKT_LAYOUT_VERSION ||
        h->header_size != sizeof(vkt_ring_header) || h->slot_count == 0 ||
        need > (uint64_t)st.st_size ||
        h->pixels_offset + (uint64_t)h->row_stride * h->height > h->slot_size) {
        munmap(p, (size_t)st.st_size); close(fd); errno = EPROTO; return -1;
    }
    r->fd = fd;
    r->base = (const uint8_t *)p;
    r->size = (size_t)st.st_size;
    r->generation = h->generation;
    return 0;
}

static inline void vkt_ring_close(vkt_ring *r) {
    if (r->base) munmap((void *)r->base, r->size);
    if (r->fd >= 0) close(r->fd);
    r->base = NULL;
    r->fd = -1;
}

static inline size_t vkt_ring_pixel_bytes(const vkt_ring *r) {
    return (size_t)vkt_header(r)->row_stride * vkt_header(r)->height;
}

static inline const vkt_slot_header *vkt__slot(const vkt_ring *r, uint64_t frame) {
    const vkt_ring_header *h = vkt_header(r);
    return (const vkt_slot_header *)(r->base + h->header_size +
                                     (size_t)(frame % h->slot_count) * h->slot_size);
}

/* Seqlock copy of the slot holding `frame`: 1 ok, 0 torn/being written, -1 empty. */
static inline int vkt__read_slot(const vkt_ring *r, uint64_t frame, vkt_frame_meta *meta,
                                 void *pixels, size_t cap) {
    const vkt_slot_header *s = vkt__slot(r, frame);
    uint64_t s1 = atomic_load_explicit(&s->seq, memory_order_acquire);
    if (s1 == 0) return -1;
    if (s1 & 1) return 0;
    memcpy(meta, (const void *)&s->meta, sizeof *meta);
    size_t n = vkt_ring_pixel_bytes(r);
    if (pixels && cap >= n)
        memcpy(pixels, (const uint8_t *)s + vkt_header(r)->pixels_offset, n);
    atomic_thread_fence(memory_order_acquire);
    uint64_t s2 = atomic_load_explicit(&s->seq, memory_order_relaxed);
    return (s1 == s2 && meta->frame == (s1 - 2) / 2) ? 1 : 0;
}

/* Whether /dev/shm/<name> now names a different segment; if so, re-open it (1). */
static inline int vkt__try_reopen(vkt_ring *r) {
    char path[270];
    snprintf(path, sizeof path, "/dev/shm/%s", r->name);
    struct stat a, b;
    if (fstat(r->fd, &a) != 0 || stat(path, &b) != 0) return 0;
    if (a.st_ino == b.st_ino && a.st_dev == b.st_dev) return 0;
    vkt_ring fresh;
    if (vkt_ring_open(&fresh, r->name) != 0) return 0;
    if (fresh.generation == r->generation) { vkt_ring_close(&fresh); return 0; }
    fresh.received = r->received;
    fresh.lost = r->lost;
    fresh.torn_retries = r->torn_retries;
    fresh.restarts = r->restarts + 1;
    vkt_ring_close(r);
    *r = fresh;
    return 1;
}

static inline uint64_t vkt__now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

/* Blocks (futex) until a frame newer than the last one returned, at most timeout_ms.
 * On VKT_FRAME, *meta and pixels (if cap is large enough) hold a verified copy of the newest
 * frame; frames skipped since the previous one are added to r->lost. */
static inline int vkt_ring_wait_next(vkt_ring *r, int timeout_ms, vkt_frame_meta *meta,
                                     void *pixels, size_t cap) {
    uint64_t deadline = vkt__now_ms() + (uint64_t)(timeout_ms < 0 ? 0 : timeout_ms);
    for (;;) {
        const vkt_ring_header *h = vkt_header(r);
        uint32_t wake = atomic_load_explicit(&h->wake, memory_order_acquire);
        uint64_t latest = atomic_load_explicit(&h->latest, memory_order_acquire);
        if (latest != VKT_NO_FRAME && (r->last == VKT_NO_FRAME || latest > r->last)) {
            int ok = vkt__read_slot(r, latest, meta, pixels, cap);
            if (ok == 1 && (r->last == VKT_NO_FRAME || meta->frame > r->last)) {
                if (r->last != VKT_NO_FRAME) r->lost += meta->frame - r->last - 1;
                r->last = meta->frame;
                r->received++;
                return VKT_FRAME;
            }
            if (ok == 0) { r->torn_retries++; continue; }
        }
        uint32_t state = atomic_load_explicit(&h->state, memory_order_acquire);
        uint64_t now = vkt__now_ms();
        if (state != VKT_STATE_LIVE) {
            if (vkt__try_reopen(r)) return VKT_RESTARTED;
            if (state == VKT_STATE_CLOSED || now >= deadline) return VKT_CLOSED;
            usleep(10000);
            continue;
        }
        if (now >= deadline) return VKT_TIMEOUT;
        uint64_t left = deadline - now;
        if (left > 100) left = 100; /* re-check for a replaced segment every 100 ms */
        struct timespec ts = {(time_t)(left / 1000), (long)(left % 1000) * 1000000L};
        syscall(SYS_futex, &h->wake, FUTEX_WAIT, wake, &ts, NULL, 0);
        if (atomic_load_explicit(&h->wake, memory_order_acquire) == wake && vkt__try_reopen(r))
            return VKT_RESTARTED;
    }
}

#endif /* VKTERRAIN_RING_H */
