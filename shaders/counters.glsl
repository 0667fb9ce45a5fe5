// Counting the work done (issue 5): with #define COUNT_EVALUATIONS, count_event(COUNTER_*) adds 1 to a
// counter of the SSBO at binding SKIP_COUNTER_BINDING (the renderer zeroes and reads it); otherwise it
// compiles to nothing. Included by skip.glsl (the network) and reference.glsl (the volume look-up).

const int COUNTER_FRAGMENTS = 0;      // fragments that reached the shading code (covered / in-disc pixels)
const int COUNTER_EVALUATIONS = 1;    // MLP evaluations (reference renders: volume look-ups)
const int COUNTER_SKIPPED_A_ZERO = 2; // skipped: A = 0, back face, no irradiance
const int COUNTER_SKIPPED_BOUND = 3;  // skipped: the bound cannot reach the display's smallest step
const int COUNTER_BACKGROUND = 4;     // pixels with no surface (BRDF slice: outside the unit disc)
const int COUNTER_COUNT = 8;

#ifdef COUNT_EVALUATIONS
layout(std430, binding = SKIP_COUNTER_BINDING) buffer SkipCounters {
    uint skip_counters[COUNTER_COUNT];
};
#endif

void count_event(int counter) {
#ifdef COUNT_EVALUATIONS
    atomicAdd(skip_counters[counter], 1u);
#endif
}

