/* Reference paced loop for benchmarks/bench_daq.py: wake every period with
 * clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) and record how late each wake-up is.
 * Usage: c_paced_loop PERIOD_US CYCLES
 * Prints one line: "cycles=N missed=M p50_us=.. p99_us=.. max_us=.."
 * A wake-up later than half a period is a missed deadline (the criterion the Python paced
 * clock uses); after a whole period of delay the schedule is re-anchored, as in daq.runtime.runner. */
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static long long ns(const struct timespec *t) { return t->tv_sec * 1000000000LL + t->tv_nsec; }

static int cmp(const void *a, const void *b) {
    long long x = *(const long long *)a, y = *(const long long *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv) {
    if (argc != 3) { fprintf(stderr, "usage: %s PERIOD_US CYCLES\n", argv[0]); return 2; }
    long long period = atoll(argv[1]) * 1000LL;
    long n = atol(argv[2]);
    long long *late = malloc(sizeof(long long) * (size_t)n);
    if (!late) return 1;
    struct timespec now, next;
    clock_gettime(CLOCK_MONOTONIC, &next);
    long long t_next = ns(&next) + period;
    long missed = 0;
    for (long i = 0; i < n; i++) {
        next.tv_sec = t_next / 1000000000LL;
        next.tv_nsec = t_next % 1000000000LL;
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL) != 0) {}
        clock_gettime(CLOCK_MONOTONIC, &now);
        long long l = ns(&now) - t_next;
        late[i] = l;
        if (l > period / 2) missed++;
        if (l > period) t_next = ns(&now);
        t_next += period;
    }
    qsort(late, (size_t)n, sizeof(long long), cmp);
    printf("cycles=%ld missed=%ld p50_us=%.1f p99_us=%.1f max_us=%.1f\n", n, missed,
           late[n / 2] / 1e3, late[(long)(n * 0.99)] / 1e3, late[n - 1] / 1e3);
    free(late);
    return 0;
}
