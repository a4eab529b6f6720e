/* The no-work peer of bench_drives_realtime.py in C: the same pacing as drives.realtime.Pacer
 * (absolute slots every 1 ms, sleep to 250 us before the slot, then spin; a slot a whole
 * period gone is skipped and counted) with nothing to do in the cycle. Late slots here are
 * the box's (scheduler, other processes, the VM), not Python's nor the drives'.
 *
 *   gcc -O2 -o rt_peer bench/rt_peer.c && ./rt_peer SECONDS [FIFO_PRIORITY [CPU]]
 *
 * Prints one JSON object. A measurement tool, not part of the package.
 */
#define _GNU_SOURCE
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PERIOD_S 1e-3
#define SPIN_S 250e-6

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static int by_value(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv)
{
    double seconds = argc > 1 ? atof(argv[1]) : 60.0;
    int priority = argc > 2 ? atoi(argv[2]) : 0;
    int cpu = argc > 3 ? atoi(argv[3]) : -1; /* -1: any CPU */
    long cycles = (long)(seconds / PERIOD_S + 0.5), late = 0, skipped = 0;
    char scheduling[96] = "SCHED_OTHER";
    if (cycles <= 0 || priority < 0 || priority > 99) {
        fprintf(stderr, "usage: rt_peer SECONDS>0 [FIFO_PRIORITY 0..99 [CPU]]\n");
        return 2;
    }
    if (cpu >= 0) {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(cpu, &one);
        if (sched_setaffinity(0, sizeof one, &one) != 0)
            cpu = -1;
    }
    if (priority) {
        struct sched_param p = {.sched_priority = priority};
        if (sched_setscheduler(0, SCHED_FIFO, &p) == 0)
            snprintf(scheduling, sizeof scheduling, "SCHED_FIFO %d", priority);
        else
            snprintf(scheduling, sizeof scheduling, "SCHED_OTHER (SCHED_FIFO %d refused)",
                     priority);
    }
    double *lateness = calloc(cycles, sizeof *lateness);
    if (!lateness)
        return 1;
    double slot = now();
    for (long k = 0; k < cycles; k++) {
        double t = now();
        slot += PERIOD_S;
        if (t > slot + PERIOD_S) { /* whole slots gone: skip ahead, as the Pacer does */
            long missed = (long)((t - slot) / PERIOD_S);
            skipped += missed;
            slot += missed * PERIOD_S;
        }
        double remaining = slot - t;
        if (remaining > SPIN_S) {
            double s = remaining - SPIN_S;
            struct timespec ts = {(time_t)s, (long)((s - (time_t)s) * 1e9)};
            nanosleep(&ts, NULL);
        }
        while (now() < slot)
            ;
        lateness[k] = now() - slot;
        if (lateness[k] > PERIOD_S)
            late++;
    }
    qsort(lateness, cycles, sizeof *lateness, by_value);
    printf("{\"language\": \"C\", \"cycles\": %ld, \"late_cycles\": %ld, \"skipped_slots\": %ld, "
           "\"late_or_missed_slots\": %ld, \"late_or_missed_pct\": %.4f, "
           "\"lateness_p50_us\": %.1f, \"lateness_p99_us\": %.1f, \"lateness_max_us\": %.1f, "
           "\"scheduling\": \"%s\", \"cpu\": %d}\n",
           cycles, late, skipped, late + skipped, 100.0 * (late + skipped) / (cycles + skipped),
           lateness[cycles / 2] * 1e6, lateness[cycles * 99 / 100] * 1e6,
           lateness[cycles - 1] * 1e6, scheduling, cpu);
    free(lateness);
    return 0;
}
