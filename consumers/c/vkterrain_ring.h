/*
 * vkterrain_ring.h: read frames from a vkterrain shared-memory ring (layout version 2).
 * Single header, C11, Linux. See docs/ring.md for the protocol and the threat model; a test
 * compiles this file and checks every offset below against the Rust layout
 * (src/output/ring/layout.rs). Define _GNU_SOURCE before including it.
 *
 *   vkt_ring r;
 *   if (vkt_ring_open(&r, "vkterrain") != 0) ...;          // $VKTERRAIN_RING_DIR or /run/vkterrain
 *   vkt_frame_meta m;
 *   int ev = vkt_ring_wait_next(&r, 1000, &m, buf, bufsize); // VKT_FRAME, VKT_TIMEOUT, ...
 *   vkt_ring_close(&r);
 *
 * Trust: a ring is accepted only if it is a regular file owned by the expected user (given, or
 * $VKTERRAIN_RING_OWNER, or else the owner of a ring directory that nobody else can write) that
 * nobody else may write. Every header field is checked against the mapped size once, at open;
 * the checked copy in vkt_ring is all that is used afterwards, and every slot's metadata is
 * checked against it before a frame is returned.
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
#include <stdlib.h>
#include <string.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <pwd.h>
#include <time.h>
#include <unistd.h>
#include <stdatomic.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <linux/futex.h>

#ifndef F_OFD_GETLK
#define F_OFD_GETLK 36
#endif

#define VKT_MAGIC 0x31474E4952544B56ull /* "VKTRING1" little-endian */
#define VKT_LAYOUT_VERSION 3u
#define VKT_FLAG_ZERO_COPY 1u
#define VKT_DEFAULT_DIR "/run/vkterrain"
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
    uint32_t header_size;      /*  12: where slot 0 starts */
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
    uint32_t producer_pid;     /*  60: informational; liveness is the producer's lock */
    /* line 1 */
    _Atomic uint64_t latest;   /*  64: newest published frame, VKT_NO_FRAME before the first */
    _Atomic uint32_t state;    /*  72 */
    uint32_t flags;            /*  76: VKT_FLAG_ZERO_COPY */
    uint8_t _pad1[48];
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
    uint32_t height_datum;     /* 192: 0 none (WGS84 fields NaN), 1 ellipsoid, 2 EGM96, 3 EGM2008 */
    uint32_t _reserved1;       /* 196 */
    double lat_deg;            /* 200: WGS84 */
    double lon_deg;            /* 208 */
    double height_m;           /* 216: above height_datum */
    double heading_deg;        /* 224: local NED, clockwise from true north */
    double local_pitch_deg;    /* 232: nose up */
    double local_roll_deg;     /* 240: right wing down */
    uint64_t _reserved2;       /* 248 */
} vkt_frame_meta;              /* 256 bytes */

typedef struct vkt_slot_header {
    _Atomic uint64_t seq;      /*   0: seqlock */
    uint8_t _pad0[56];
    vkt_frame_meta meta;       /*  64 */
} vkt_slot_header;             /* 320 bytes; pixels follow at pixels_offset */

_Static_assert(sizeof(vkt_ring_header) == 256, "ring header size");
_Static_assert(sizeof(vkt_slot_header) == 320, "slot header size");
_Static_assert(sizeof(vkt_frame_meta) == 256, "frame meta size");

enum { VKT_FRAME = 0, VKT_TIMEOUT = 1, VKT_CLOSED = 2, VKT_RESTARTED = 3, VKT_ERROR = -1 };

typedef struct vkt_ring {
    char name[256];
    int fd;
    const uint8_t *base;
    size_t size;
    uint64_t generation;
    uint64_t last;        /* last frame returned, VKT_NO_FRAME before the first */
    uint64_t received, lost, torn_retries, restarts, bad_slots;
    /* The checked header (never re-read from the segment after open). */
    uint32_t width, height, row_stride, slot_count, depth_format, flags;
    uint64_t header_size, slot_size, pixels_offset, depth_offset, pixel_bytes;
    uid_t owner;
    char dir[PATH_MAX];
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

/* Checks the constant line of a header against a segment of `mapped` bytes and stores the
 * checked values in `r`. 0 on success; -1 (errno EPROTO) if any field does not fit. */
static inline int vkt__check_header(const vkt_ring_header *h, uint64_t mapped, vkt_ring *r) {
    uint64_t w = h->width, ht = h->height, px = (uint64_t)h->row_stride * ht;
    uint64_t hs = h->header_size, ss = h->slot_size, po = h->pixels_offset, dof = h->depth_offset;
    int ok = h->magic == VKT_MAGIC && h->layout_version == VKT_LAYOUT_VERSION &&
             hs >= sizeof(vkt_ring_header) && hs % 64 == 0 && hs <= 65536 &&
             w >= 1 && w <= 16384 && ht >= 1 && ht <= 16384 &&
             h->pixel_format == VKT_FORMAT_RGBA8_SRGB && (uint64_t)h->row_stride == 4 * w &&
             h->slot_count >= 2 && h->slot_count <= 64 &&
             (h->depth_format == VKT_DEPTH_NONE || h->depth_format == VKT_DEPTH_F32_REVERSED_Z) &&
             ss % 64 == 0 && po >= sizeof(vkt_slot_header) && po % 64 == 0 && po + px <= ss;
    if (ok && h->depth_format == VKT_DEPTH_F32_REVERSED_Z)
        ok = dof % 64 == 0 && dof >= po + px && dof + w * ht * 4 <= ss;
    else if (ok)
        ok = dof == 0;
    if (ok) ok = hs + ss * h->slot_count <= mapped;
    if (!ok) { errno = EPROTO; return -1; }
    r->width = h->width; r->height = h->height; r->row_stride = h->row_stride;
    r->slot_count = h->slot_count; r->depth_format = h->depth_format; r->flags = h->flags;
    r->header_size = hs; r->slot_size = ss; r->pixels_offset = po; r->depth_offset = dof;
    r->pixel_bytes = px; r->generation = h->generation;
    return 0;
}

/* Whose rings to accept in `dir` when no owner is given: the directory's owner, if neither it
 * nor any directory above it can be written by anyone but root and that owner. -1 otherwise. */
static inline int vkt__dir_owner(const char *dir, uid_t *owner) {
    char path[PATH_MAX];
    struct stat st;
    if (!realpath(dir, path) || stat(path, &st) != 0) return -1;
    *owner = st.st_uid;
    for (;;) {
        if (stat(path, &st) != 0) return -1;
        if ((st.st_uid != 0 && st.st_uid != *owner) || (st.st_mode & 022)) { errno = EPERM; return -1; }
        char *slash = strrchr(path, '/');
        if (!slash || slash == path) {
            if (strcmp(path, "/") == 0) return 0;
            path[1] = '\0';
            continue;
        }
        *slash = '\0';
    }
}

/* Opens <dir>/<name> read-only and checks it: owned by `owner` ((uid_t)-1: the owner of a ring
 * directory nobody else can write), not writable by group or others, every header field inside
 * the mapping. 0 on success, -1 with errno set (EPERM: not trusted, EPROTO: bad header). */
static inline int vkt_ring_open_at(vkt_ring *r, const char *dir, const char *name, uid_t owner) {
    memset(r, 0, sizeof *r);
    r->fd = -1;
    r->last = VKT_NO_FRAME;
    if (!vkt__name_ok(name) || strlen(dir) + strlen(name) + 2 > PATH_MAX) { errno = EINVAL; return -1; }
    if (owner == (uid_t)-1 && vkt__dir_owner(dir, &owner) != 0) return -1;
    strcpy(r->name, name);
    strcpy(r->dir, dir);
    r->owner = owner;
    char path[PATH_MAX + 256];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    if (fd < 0) return -1;
    struct stat st;
    if (fstat(fd, &st) != 0) { close(fd); return -1; }
    if (!S_ISREG(st.st_mode) || st.st_uid != owner || (st.st_mode & 022)) {
        close(fd); errno = EPERM; return -1;
    }
    if ((size_t)st.st_size < sizeof(vkt_ring_header)) { close(fd); errno = EPROTO; return -1; }
    void *p = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_SHARED, fd, 0);
    if (p == MAP_FAILED) { close(fd); return -1; }
    if (vkt__check_header((const vkt_ring_header *)p, (uint64_t)st.st_size, r) != 0) {
        munmap(p, (size_t)st.st_size); close(fd); errno = EPROTO; return -1;
    }
    r->fd = fd;
    r->base = (const uint8_t *)p;
    r->size = (size_t)st.st_size;
    return 0;
}

/* Opens `name` in $VKTERRAIN_RING_DIR (default /run/vkterrain), owned by $VKTERRAIN_RING_OWNER
 * (a user name or uid; default: the directory's owner, see vkt_ring_open_at). */
static inline int vkt_ring_open(vkt_ring *r, const char *name) {
    const char *dir = getenv("VKTERRAIN_RING_DIR");
    const char *who = getenv("VKTERRAIN_RING_OWNER");
    uid_t owner = (uid_t)-1;
    if (!dir || !*dir) dir = VKT_DEFAULT_DIR;
    if (who && *who) {
        char *end;
        unsigned long v = strtoul(who, &end, 10);
        if (*end == '\0') owner = (uid_t)v;
        else {
            struct passwd *pw = getpwnam(who);
            if (!pw) { errno = EINVAL; return -1; }
            owner = pw->pw_uid;
        }
    }
    return vkt_ring_open_at(r, dir, name, owner);
}

static inline void vkt_ring_close(vkt_ring *r) {
    if (r->base) munmap((void *)r->base, r->size);
    if (r->fd >= 0) close(r->fd);
    r->base = NULL;
    r->fd = -1;
}

static inline size_t vkt_ring_pixel_bytes(const vkt_ring *r) {
    return (size_t)r->pixel_bytes;
}

/* Whether a producer process holds the segment (its lock; a crashed producer's segment still
 * says "live" in its state word). 1 alive, 0 not, -1 error. */
static inline int vkt_ring_producer_alive(const vkt_ring *r) {
    struct flock fl;
    memset(&fl, 0, sizeof fl);
    fl.l_type = F_RDLCK;
    fl.l_whence = SEEK_SET;
    if (fcntl(r->fd, F_OFD_GETLK, &fl) != 0) return -1;
    return fl.l_type == F_WRLCK;
}

static inline const vkt_slot_header *vkt__slot(const vkt_ring *r, uint64_t frame) {
    return (const vkt_slot_header *)(r->base + r->header_size +
                                     (size_t)(frame % r->slot_count) * r->slot_size);
}

/* Seqlock copy of the slot holding `frame`: 1 ok, 0 torn/being written, -1 empty, 2 the slot's
 * metadata disagrees with the header (never returned as a frame). */
static inline int vkt__read_slot(const vkt_ring *r, uint64_t frame, vkt_frame_meta *meta,
                                 void *pixels, size_t cap) {
    const vkt_slot_header *s = vkt__slot(r, frame);
    uint64_t s1 = atomic_load_explicit(&s->seq, memory_order_acquire);
    if (s1 == 0) return -1;
    if (s1 & 1) return 0;
    memcpy(meta, (const void *)&s->meta, sizeof *meta);
    size_t n = vkt_ring_pixel_bytes(r);
    if (pixels && cap >= n)
        memcpy(pixels, (const uint8_t *)s + r->pixels_offset, n);
    atomic_thread_fence(memory_order_acquire);
    uint64_t s2 = atomic_load_explicit(&s->seq, memory_order_relaxed);
    if (s1 != s2 || meta->frame != (s1 - 2) / 2) return 0;
    if (meta->width != r->width || meta->height != r->height || meta->row_stride != r->row_stride)
        return 2;
    return 1;
}

/* Whether <dir>/<name> now names a different segment; if so, re-open it (1). */
static inline int vkt__try_reopen(vkt_ring *r) {
    char path[PATH_MAX + 256];
    snprintf(path, sizeof path, "%s/%s", r->dir, r->name);
    struct stat a, b;
    if (fstat(r->fd, &a) != 0 || lstat(path, &b) != 0) return 0;
    if (a.st_ino == b.st_ino && a.st_dev == b.st_dev) return 0;
    vkt_ring fresh;
    if (vkt_ring_open_at(&fresh, r->dir, r->name, r->owner) != 0) return 0;
    if (fresh.generation == r->generation) { vkt_ring_close(&fresh); return 0; }
    fresh.received = r->received;
    fresh.lost = r->lost;
    fresh.torn_retries = r->torn_retries;
    fresh.bad_slots = r->bad_slots;
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
    uint64_t torn = 0;
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
            if (ok == 0) {
                /* Being written or overwritten: retry, never past the deadline (a slot a
                 * crashed or hostile producer left odd stays odd). */
                r->torn_retries++;
                if (vkt__now_ms() >= deadline) return VKT_TIMEOUT;
                if (++torn % 64 == 0) usleep(100);
                continue;
            }
            if (ok == 2) { r->bad_slots++; r->last = latest; }
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
