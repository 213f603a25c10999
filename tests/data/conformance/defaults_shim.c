/* Linked into GRBL 1.1h's validator (gvalidate.exe's objects, unchanged)
   by generate.py, which also passes
   -Wl,--wrap=plan_check_full_buffer,--wrap=protocol_buffer_synchronize.
   - The validator enters GRBL's protocol loop without ever calling
     settings_init(), so it would run with every $ setting at zero: GRBL's
     own settings_restore() runs first, as at a new board's first boot.
   - The validator has no stepper: it drops the planned moves at each
     byte it reads. A line that plans more than the planner's 15 blocks
     (an arc's chords) or waits for the planner to empty (M-codes, G4 after
     a move on the same line) would wait forever; here the planner is
     emptied instead, as a machine that ran the moves would have it. */
#include <stdint.h>
void settings_restore(uint8_t restore_flag);
void plan_reset(void);
__attribute__((constructor)) static void grbl_defaults(void) { settings_restore(0xFF); }
uint8_t __wrap_plan_check_full_buffer(void) { plan_reset(); return 0; }
void __wrap_protocol_buffer_synchronize(void) { plan_reset(); }
