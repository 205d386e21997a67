/* standalone.c - a main for the fuzz targets where clang's libFuzzer is not available: each
   file named on the command line is fed once to LLVMFuzzerTestOneInput, so the corpus runs as
   a regression test (tests/fuzz/run.sh --replay). Prints "N inputs" when all returned. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int main(int argc, char **argv) {
    int i, n = 0;
    for (i = 1; i < argc; ++i) {
        FILE *f = fopen(argv[i], "rb");
        unsigned char *buf = NULL;
        size_t len = 0, cap = 0, got;
        if (!f) {
            fprintf(stderr, "standalone: cannot open %s\n", argv[i]);
            return 2;
        }
        do { /* read it whole */
            if (len == cap) {
                unsigned char *nb = (unsigned char *)realloc(buf, cap = cap ? 2 * cap : 4096);
                if (!nb) {
                    fprintf(stderr, "standalone: out of memory reading %s\n", argv[i]);
                    free(buf);
                    fclose(f);
                    return 2;
                }
                buf = nb;
            }
            got = fread(buf + len, 1, cap - len, f);
            len += got;
        } while (got > 0);
        fclose(f);
        LLVMFuzzerTestOneInput(buf, len);
        free(buf);
        n++;
    }
    printf("%d inputs\n", n);
    return 0;
}
