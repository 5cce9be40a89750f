int fogbeam_airlight_placeholder = 0;
