/* End of the slow core's names (see relaxation_begin.h). */
#undef cell
#undef node
#undef everett
#undef branch
#undef branch_slope
#undef core_move
#undef NN
#undef EV
#undef V_LO
#undef H
