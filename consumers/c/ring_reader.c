/*
 * ring_reader: example consumer of a vkterrain ring, in C with vkterrain_ring.h.
 *
 *   cc -O2 -std=c11 -o ring_reader ring_reader.c
 *   ./ring_reader NAME [--dir D] [--owner USER|UID] [--seconds S] [--frames N] [--timeout-ms T]
 *                 [--verify] [--save OUT.ppm] [--ready FILE]
 *   ./ring_reader --layout          # prints the header's offsets and sizes (tests use it)
 *
 * Without --dir/--owner: $VKTERRAIN_RING_DIR (default /run/vkterrain) and $VKTERRAIN_RING_OWNER
 * (default: the owner of the directory, if nobody else can write it).
 *
 * Reads frames until S seconds pass, N frames arrived or the ring closes, then prints one line
 * of counters. --verify checks the test pattern of tests/ring.rs (frame number in bytes 0..8 and
 * CRC-32 of bytes 16.. in bytes 8..12). --save writes the last frame as a binary PPM (RGB).
 * --ready creates FILE once the first frame has been read (a supervisor, or a test, knows the
 * reader is attached).
 */
#define _GNU_SOURCE
#include "vkterrain_ring.h"

#include <stdio.h>
#include <stdlib.h>

static uint32_t crc_table[256];

static void crc_init(void) {
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        crc_table[i] = c;
    }
}

static uint32_t crc32_of(const uint8_t *p, size_t n) {
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) c = crc_table[(c ^ p[i]) & 0xFF] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

static uint64_t rd64(const uint8_t *p) {
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

#define OFF(t, f) printf("%s.%s %zu\n", #t, #f, offsetof(t, f))
static void print_layout(void) {
    printf("vkt_ring_header.size %zu\n", sizeof(vkt_ring_header));
    OFF(vkt_ring_header, magic); OFF(vkt_ring_header, layout_version);
    OFF(vkt_ring_header, header_size); OFF(vkt_ring_header, generation);
    OFF(vkt_ring_header, width); OFF(vkt_ring_header, height);
    OFF(vkt_ring_header, pixel_format); OFF(vkt_ring_header, row_stride);
    OFF(vkt_ring_header, slot_count); OFF(vkt_ring_header, depth_format);
    OFF(vkt_ring_header, slot_size); OFF(vkt_ring_header, pixels_offset);
    OFF(vkt_ring_header, depth_offset); OFF(vkt_ring_header, producer_pid);
    OFF(vkt_ring_header, latest); OFF(vkt_ring_header, state); OFF(vkt_ring_header, flags);
    OFF(vkt_ring_header, wake); OFF(vkt_ring_header, published);
    printf("vkt_slot_header.size %zu\n", sizeof(vkt_slot_header));
    OFF(vkt_slot_header, seq); OFF(vkt_slot_header, meta);
    printf("vkt_frame_meta.size %zu\n", sizeof(vkt_frame_meta));
    OFF(vkt_frame_meta, frame); OFF(vkt_frame_meta, capture_ns); OFF(vkt_frame_meta, publish_ns);
    OFF(vkt_frame_meta, width); OFF(vkt_frame_meta, height); OFF(vkt_frame_meta, row_stride);
    OFF(vkt_frame_meta, position); OFF(vkt_frame_meta, yaw_deg); OFF(vkt_frame_meta, pitch_deg);
    OFF(vkt_frame_meta, roll_deg); OFF(vkt_frame_meta, vfov_deg); OFF(vkt_frame_meta, near_m);
    OFF(vkt_frame_meta, far_m); OFF(vkt_frame_meta, fx); OFF(vkt_frame_meta, fy);
    OFF(vkt_frame_meta, cx); OFF(vkt_frame_meta, cy); OFF(vkt_frame_meta, gpu_prepass_ms);
    OFF(vkt_frame_meta, gpu_terrain_ms); OFF(vkt_frame_meta, gpu_readback_ms);
    OFF(vkt_frame_meta, cpu_record_ms); OFF(vkt_frame_meta, cpu_wait_ms);
    OFF(vkt_frame_meta, triangles); OFF(vkt_frame_meta, height_datum);
    OFF(vkt_frame_meta, lat_deg); OFF(vkt_frame_meta, lon_deg); OFF(vkt_frame_meta, height_m);
    OFF(vkt_frame_meta, heading_deg); OFF(vkt_frame_meta, local_pitch_deg);
    OFF(vkt_frame_meta, local_roll_deg); OFF(vkt_frame_meta, _reserved2);
}

static int save_ppm(const char *path, const uint8_t *rgba, uint32_t w, uint32_t h) {
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "wb");
    if (!f) return -1;
    fprintf(f, "P6\n%u %u\n255\n", w, h);
    for (size_t i = 0; i < (size_t)w * h; i++) fwrite(rgba + 4 * i, 1, 3, f);
    if (fclose(f) != 0) return -1;
    return rename(tmp, path);
}

int main(int argc, char **argv) {
    if (argc >= 2 && strcmp(argv[1], "--layout") == 0) { print_layout(); return 0; }
    if (argc < 2) {
        fprintf(stderr, "usage: %s NAME [--dir D] [--owner USER|UID] [--seconds S] [--frames N] "
                        "[--timeout-ms T] [--verify] [--save OUT.ppm] [--ready FILE] | --layout\n", argv[0]);
        return 2;
    }
    const char *name = argv[1], *save = NULL, *dir = NULL, *owner_arg = NULL, *ready = NULL;
    double seconds = 5.0;
    unsigned long long max_frames = 0;
    int timeout_ms = 5000, verify = 0;
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--seconds") && i + 1 < argc) seconds = atof(argv[++i]);
        else if (!strcmp(argv[i], "--frames") && i + 1 < argc) max_frames = strtoull(argv[++i], 0, 10);
        else if (!strcmp(argv[i], "--timeout-ms") && i + 1 < argc) timeout_ms = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--verify")) verify = 1;
        else if (!strcmp(argv[i], "--save") && i + 1 < argc) save = argv[++i];
        else if (!strcmp(argv[i], "--ready") && i + 1 < argc) ready = argv[++i];
        else if (!strcmp(argv[i], "--dir") && i + 1 < argc) dir = argv[++i];
        else if (!strcmp(argv[i], "--owner") && i + 1 < argc) owner_arg = argv[++i];
        else { fprintf(stderr, "error: unknown argument %s\n", argv[i]); return 2; }
    }
    crc_init();
    if (dir) setenv("VKTERRAIN_RING_DIR", dir, 1);
    if (owner_arg) setenv("VKTERRAIN_RING_OWNER", owner_arg, 1);
    vkt_ring r;
    uint64_t t_open = vkt__now_ms();
    while (vkt_ring_open(&r, name) != 0) {
        if (errno == EPERM || errno == EPROTO) { /* not a ring we trust: no point in waiting */
            fprintf(stderr, "error: refusing ring %s: %s\n", name,
                    errno == EPERM ? "not owned by the expected user, or writable by others"
                                   : "invalid header");
            return 1;
        }
        if (vkt__now_ms() - t_open > (uint64_t)timeout_ms) {
            fprintf(stderr, "error: cannot open ring %s: %s\n", name, strerror(errno));
            return 1;
        }
        usleep(10000);
    }
    size_t cap = vkt_ring_pixel_bytes(&r);
    uint8_t *buf = malloc(cap);
    if (!buf) return 1;
    uint64_t end = vkt__now_ms() + (uint64_t)(seconds * 1000.0);
    unsigned long long bad = 0, nonincreasing = 0, gaps = 0;
    uint64_t prev = VKT_NO_FRAME;
    vkt_frame_meta m, last_meta = {0};
    uint8_t *keep = NULL; /* the last accepted frame, for --save (buf may hold a torn copy) */
    int have = 0, closed = 0;
    while (vkt__now_ms() < end && (max_frames == 0 || r.received < max_frames)) {
        if (cap < vkt_ring_pixel_bytes(&r)) { /* a restart may change the resolution */
            cap = vkt_ring_pixel_bytes(&r);
            buf = realloc(buf, cap);
            if (!buf) return 1;
        }
        int ev = vkt_ring_wait_next(&r, timeout_ms, &m, buf, cap);
        if (ev == VKT_CLOSED) { closed = 1; break; }
        if (ev == VKT_RESTARTED) { prev = VKT_NO_FRAME; continue; }
        if (ev != VKT_FRAME) continue;
        if (prev != VKT_NO_FRAME) {
            if (m.frame <= prev) nonincreasing++;
            else gaps += m.frame - prev - 1;
        }
        prev = m.frame;
        size_t n = (size_t)m.row_stride * m.height;
        if (verify && (n < 16 || rd64(buf) != m.frame ||
                       (uint32_t)rd64(buf + 8) != crc32_of(buf + 16, n - 16)))
            bad++;
        last_meta = m;
        if (ready && !have) {
            FILE *f = fopen(ready, "w");
            if (!f || fclose(f) != 0) {
                fprintf(stderr, "error: cannot create %s\n", ready);
                return 1;
            }
        }
        have = 1;
        if (save) {
            uint8_t *k = realloc(keep, n);
            if (!k) return 1;
            keep = k;
            memcpy(keep, buf, n);
        }
    }
    if (save && have && save_ppm(save, keep, last_meta.width, last_meta.height) != 0) {
        fprintf(stderr, "error: cannot write %s\n", save);
        return 1;
    }
    printf("received=%llu lost=%llu gaps=%llu bad=%llu nonincreasing=%llu torn_retries=%llu "
           "restarts=%llu bad_slots=%llu closed=%d\n",
           (unsigned long long)r.received, (unsigned long long)r.lost, gaps, bad, nonincreasing,
           (unsigned long long)r.torn_retries, (unsigned long long)r.restarts,
           (unsigned long long)r.bad_slots, closed);
    vkt_ring_close(&r);
    free(buf);
    free(keep);
    return 0;
}
