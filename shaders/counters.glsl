// Counting the work done (issue 5): with #define COUNT_EVALUATIONS, count_event(COUNTER_*) adds 1 to a
// counter of the SSBO at binding SKIP_COUNTER_BINDING (the renderer zeroes and reads it); otherwise it
// compiles to nothing. Included by skip.glsl (the network) and reference.glsl (the volume look-up).
//
// The counters (codes.glsl, from gratnet/codes.py's COUNTER table; COUNTER_COUNT slots in all):
//   COUNTER_FRAGMENTS       fragments that reached the shading code (covered / in-disc pixels)
//   COUNTER_EVALUATIONS     MLP evaluations (reference renders: volume look-ups)
//   COUNTER_SKIPPED_A_ZERO  skipped: A = 0, back face, no irradiance
//   COUNTER_SKIPPED_BOUND   skipped: the bound cannot reach the display's smallest step
//   COUNTER_BACKGROUND      pixels with no surface (BRDF slice: outside the unit disc)

#include "codes.glsl"

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

