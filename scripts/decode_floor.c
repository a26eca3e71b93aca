/* The floor of decode + bin: a plain C loop over a Generic T3 (HydraHarp
 * v2 / MultiHarp) PTU file's records, read in 4 MiB chunks, histogramming
 * every photon's micro time into BINS one-unit bins of one pixel, counting
 * overflows, markers and photons outside the window. No header checks, no
 * ledger, no output file: what a hand-written loop costs on this machine.
 *
 *   cc -O2 -o decode_floor scripts/decode_floor.c
 *   ./decode_floor FILE.ptu BINS
 */
#define _GNU_SOURCE /* memmem */
#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: decode_floor FILE.ptu BINS\n");
        return 2;
    }
    int fd = open(argv[1], O_RDONLY);
    uint32_t bins = (uint32_t)atol(argv[2]);
    if (fd < 0 || bins == 0) {
        perror(argv[1]);
        return 2;
    }
    /* The records start after the 48-byte Header_End tag entry. */
    static char head[1 << 16];
    ssize_t got = read(fd, head, sizeof head);
    char *end = got > 0 ? memmem(head, (size_t)got, "Header_End", 10) : NULL;
    if (!end) {
        fprintf(stderr, "%s: no Header_End tag\n", argv[1]);
        return 2;
    }
    lseek(fd, (off_t)(end - head) + 48, SEEK_SET);
    size_t cap = 1 << 20;
    uint32_t *buf = malloc(cap * 4);
    uint32_t *hist = calloc(bins, 4);
    uint64_t records = 0, overflows = 0, markers = 0, outside = 0;
    ssize_t r;
    while ((r = read(fd, buf, cap * 4)) > 0) {
        size_t n = (size_t)r / 4;
        records += n;
        for (size_t i = 0; i < n; i++) {
            uint32_t x = buf[i];
            if (x >> 31) {
                if (((x >> 25) & 63) == 63)
                    overflows++;
                else
                    markers++;
            } else {
                uint32_t micro = (x >> 10) & 0x7fff;
                if (micro < bins)
                    hist[micro]++;
                else
                    outside++;
            }
        }
    }
    uint64_t binned = 0;
    for (uint32_t k = 0; k < bins; k++)
        binned += hist[k];
    printf("%llu records: %llu binned, %llu outside, %llu overflows, %llu markers\n",
           (unsigned long long)records, (unsigned long long)binned,
           (unsigned long long)outside, (unsigned long long)overflows,
           (unsigned long long)markers);
    return 0;
}
