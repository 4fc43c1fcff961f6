/* Host-side check of frame.c with the machine's C compiler (no AVR needed).
 *
 *   frame_test test_vectors.json   compare frame_encode with the vectors the Python encoder wrote
 *   frame_test -                   read "seq x y" lines on stdin, print each wire frame in hex
 *                                  (the Python tests decode these with the Python decoder)
 */
#include <stdio.h>
#include <string.h>

#include "frame.h"

static void to_hex(const uint8_t *bytes, uint8_t n, char *out)
{
    for (uint8_t i = 0; i < n; i++)
        sprintf(out + 2 * i, "%02x", bytes[i]);
}

static int check_vectors(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        perror(path);
        return 2;
    }
    char line[512], want[64], got[64];
    unsigned seq, x, y, cause, checked = 0, failed = 0;
    uint8_t wire[FRAME_WIRE_LEN], boot[BOOT_WIRE_LEN];
    while (fgets(line, sizeof line, f)) {
        const char *b = strstr(line, "{\"boot_cause\"");
        if (b && sscanf(b, "{\"boot_cause\": %u, \"first_seq\": %u, \"frame\": \"%63[0-9a-f]\"",
                        &cause, &seq, want) == 3) {
            to_hex(boot, frame_encode_boot((uint8_t)cause, (uint16_t)seq, boot), got);
            checked++;
            if (strcmp(got, want) != 0) {
                failed++;
                printf("FAIL boot cause=%u first_seq=%u: C %s, Python %s\n", cause, seq, got,
                       want);
            }
            continue;
        }
        const char *v = strstr(line, "{\"seq\"");
        if (!v || sscanf(v, "{\"seq\": %u, \"x\": %u, \"y\": %u, \"frame\": \"%63[0-9a-f]\"",
                         &seq, &x, &y, want) != 4)
            continue;
        to_hex(wire, frame_encode((uint16_t)seq, (uint16_t)x, (uint16_t)y, wire), got);
        checked++;
        if (strcmp(got, want) != 0) {
            failed++;
            printf("FAIL seq=%u x=%u y=%u: C %s, Python %s\n", seq, x, y, got, want);
        }
    }
    fclose(f);
    printf("%u vectors checked, %u failed\n", checked, failed);
    return (checked == 0 || failed) ? 1 : 0;
}

static int encode_stdin(void)
{
    unsigned seq, x, y;
    uint8_t wire[FRAME_WIRE_LEN];
    char hex[64];
    while (scanf("%u %u %u", &seq, &x, &y) == 3) {
        to_hex(wire, frame_encode((uint16_t)seq, (uint16_t)x, (uint16_t)y, wire), hex);
        puts(hex);
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s test_vectors.json | -\n", argv[0]);
        return 2;
    }
    return strcmp(argv[1], "-") == 0 ? encode_stdin() : check_vectors(argv[1]);
}
