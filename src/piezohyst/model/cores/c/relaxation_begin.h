/* A relaxing (slow) Preisach core beside the main one: the grid functions of
 * preisach_grid.c follow this header again, their names mapped onto the slow core's own
 * grid and Everett table (SLOW_NN, SLOW_EV, ...); relaxation_end.h ends the mapping. */
#define cell slow_cell
#define node slow_node
#define everett slow_everett
#define branch slow_branch
#define branch_slope slow_branch_slope
#define core_move slow_move
#define NN SLOW_NN
#define EV SLOW_EV
#define V_LO SLOW_V_LO
#define H SLOW_H
