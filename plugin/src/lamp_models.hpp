// placeholder: parametric lamp models (owned by the lamp generator work)
#pragma once
