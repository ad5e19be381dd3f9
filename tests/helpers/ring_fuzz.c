/*
 * ring_fuzz: feeds vkterrain_ring.h hostile segments (tests/ring.rs builds it with
 * AddressSanitizer, so any out-of-bounds read aborts the run).
 *
 *   ring_fuzz TEMPLATE DIR COUNT SEED [--naive]
 *
 * Each case is the valid TEMPLATE mutated like tests/helpers/mutate.rs does (header fields,
 * slot metadata, sequence words, random bytes, truncation, lying geometry), written to DIR/case
 * and read with vkt_ring_open_at + vkt_ring_wait_next. Every frame returned must agree with the
 * checked header. --naive reads the way the old reader did, trusting the slot's metadata for
 * the size to copy: the negative control (ASan must catch it).
 */
#define _GNU_SOURCE
#include "vkterrain_ring.h"

#include <stdlib.h>

static uint64_t rng_state;
static uint64_t rnd(void) {
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 0x2545F4914F6CDD1Dull;
}
static uint64_t below(uint64_t n) { return n ? rnd() % n : 0; }

static const uint32_t interesting_values[] = {0, 1, 2, 3, 4, 63, 64, 65, 255, 256, 4095, 4096,
                                              8192, 16384, 16385, 65536, 0x40000001u, 0xFFFFFFFFu};
static uint32_t interesting(void) {
    if (below(4) == 0) return (uint32_t)rnd();
    return interesting_values[below(sizeof interesting_values / sizeof interesting_values[0])];
}
static void put32(uint8_t *b, size_t len, size_t off, uint32_t v) {
    if (off + 4 <= len) memcpy(b + off, &v, 4);
}
static void put64(uint8_t *b, size_t len, size_t off, uint64_t v) {
    if (off + 8 <= len) memcpy(b + off, &v, 8);
}

static size_t mutate(const uint8_t *t, size_t tlen, uint8_t *b, size_t cap) {
    memcpy(b, t, tlen);
    size_t len = tlen;
    uint32_t hs, ss, slots;
    memcpy(&hs, t + 12, 4);
    memcpy(&ss, t + 48, 4);
    memcpy(&slots, t + 40, 4);
#define SLOT(i) ((size_t)hs + ((i) % (slots ? slots : 1)) * (size_t)ss)
    static const size_t hdr[] = {8, 12, 24, 28, 32, 36, 40, 44, 48, 52, 56, 60, 76};
    static const size_t meta[] = {24, 28, 32};
    int rounds = 1 + (int)below(3);
    for (int k = 0; k < rounds; k++) {
        switch (below(6)) {
        case 0: put32(b, len, hdr[below(13)], interesting()); break;
        case 1: put32(b, len, SLOT(below(slots)) + 64 + meta[below(3)], interesting()); break;
        case 2: {
            size_t s = SLOT(below(slots));
            uint64_t v = rnd() >> below(64);
            if (below(2) == 0) put64(b, len, s, v); else put64(b, len, 64, v);
            put64(b, len, s + 64, below(8));
            break;
        }
        case 3:
            for (uint64_t n = 1 + below(16); n > 0; n--) {
                size_t hot[3] = {0, SLOT(0), SLOT(1)};
                size_t i = hot[below(3)] + below(320);
                if (i >= len) i = len ? len - 1 : 0;
                if (len) b[i] = (uint8_t)rnd();
            }
            break;
        case 4: {
            size_t nl = (size_t)below(tlen * 2 + 1);
            if (nl > cap) nl = cap;
            if (nl > len) memset(b + len, 0, nl - len);
            len = nl;
            break;
        }
        default: {
            uint32_t w = interesting();
            put32(b, len, 24, w);
            put32(b, len, 36, w * 4u);
        }
        }
    }
    return len;
}

/* The old reader's mistake: copy as many bytes as the slot's metadata claims. */
static void naive_read(const vkt_ring *r, uint8_t *out) {
    const vkt_ring_header *h = vkt_header(r);
    uint64_t latest = atomic_load(&h->latest);
    const vkt_slot_header *s = (const vkt_slot_header *)(r->base + h->header_size +
        (size_t)(latest % (h->slot_count ? h->slot_count : 1)) * h->slot_size);
    size_t n = (size_t)s->meta.row_stride * s->meta.height;
    memcpy(out, (const uint8_t *)s + h->pixels_offset, n);
}

int main(int argc, char **argv) {
    if (argc < 5) { fprintf(stderr, "usage: ring_fuzz TEMPLATE DIR COUNT SEED [--naive]\n"); return 2; }
    int naive = argc > 5 && !strcmp(argv[5], "--naive");
    FILE *f = fopen(argv[1], "rb");
    if (!f) { perror(argv[1]); return 2; }
    static uint8_t tmpl[1 << 20], buf[2 << 20];
    size_t tlen = fread(tmpl, 1, sizeof tmpl, f);
    fclose(f);
    unsigned long count = strtoul(argv[3], 0, 10);
    rng_state = strtoull(argv[4], 0, 10) | 1;
    char path[PATH_MAX + 16];
    snprintf(path, sizeof path, "%s/case", argv[2]);
    uint8_t *pixels = malloc(64u << 20), *big = malloc(1u << 30);
    unsigned long opened = 0, frames = 0, rejected = 0, violations = 0;
    for (unsigned long c = 0; c < count; c++) {
        size_t len = c == 0 ? (memcpy(buf, tmpl, tlen), tlen) : mutate(tmpl, tlen, buf, sizeof buf);
        int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
        if (fd < 0 || write(fd, buf, len) != (ssize_t)len) { perror(path); return 2; }
        close(fd);
        vkt_ring r;
        if (vkt_ring_open_at(&r, argv[2], "case", geteuid()) != 0) { rejected++; continue; }
        opened++;
        if (naive) naive_read(&r, big);
        for (int k = 0; k < 3; k++) {
            vkt_frame_meta m;
            int ev = vkt_ring_wait_next(&r, 0, &m, pixels, 64u << 20);
            if (ev != VKT_FRAME) break;
            frames++;
            if (m.width != r.width || m.height != r.height || m.row_stride != r.row_stride ||
                vkt_ring_pixel_bytes(&r) != (size_t)m.row_stride * m.height)
                violations++;
        }
        vkt_ring_close(&r);
    }
    printf("cases=%lu opened=%lu frames=%lu rejected=%lu violations=%lu\n", count, opened, frames,
           rejected, violations);
    free(pixels);
    free(big);
    return 0;
}
